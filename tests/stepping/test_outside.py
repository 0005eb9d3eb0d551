"""Particles that leave the mesh (fempm.stepping.outside): a block falling through the open
floor of its box with outside="remove" loses particles on every rank alike; what they took
(mass, momentum, kinetic energy) is accounted so that particles + removed = initial to
round-off, the energy check counts it as having left, energies.csv and summary.json say it, a
resumed run repeats the uninterrupted one; "raise" stays the default; bad policies named."""

import csv
import json

import dolfinx.fem
import dolfinx.mesh as dm
import numpy as np
import pytest
from mpi4py import MPI

import fempm
from fempm.materials import LinearElastic
from fempm.scene import Scene, run
from fempm.stepping import ExplicitSolver, Loads, StepOptions

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

G = 10.0


def falling_block(comm=MPI.COMM_WORLD, outside="remove", t_end=0.47, compiled=None) -> Scene:
    """A block 0.5 x 0.5 at 1 <= y <= 1.5 in a 1 x 2 box with no walls, falling under gravity:
    by t = 0.47 (1.1 of fall) its lower rows have left through y = 0."""
    mesh = dm.create_rectangle(comm, [[0.0, 0.0], [1.0, 2.0]], [8, 16], dm.CellType.quadrilateral)
    p = fempm.create_particles(mesh, 4, density=1000.0,
                               cells=lambda x: (x[1] > 1.0) & (x[1] < 1.5) & (x[0] > 0.25) & (x[0] < 0.75))
    p.fields["v"] = np.tile([0.3, 0.0], (len(p), 1))  # a sideways drift: momentum in x too
    return Scene(name="falling", mesh=mesh, particles=p, materials=[LinearElastic(1.0e5, 0.3)], t_end=t_end,
                 loads=Loads(body_force=(0.0, -G)), frames=0, outside=outside)


def test_removed_particles_are_accounted(tmp_path):
    scene = falling_block()
    p = scene.particles
    comm = p.comm
    m0 = comm.allreduce(float(p.mass.sum()))
    n0 = p.num_global
    out = comm.bcast(str(tmp_path), root=0)
    summary = run(scene, out, progress=False)
    removed = summary["removed"]
    assert summary["status"] == "completed" and 0 < removed["count"] < n0
    assert p.num_global + removed["count"] == n0
    assert abs(comm.allreduce(float(p.mass.sum())) + removed["mass"] - m0) < 1e-12 * m0
    final = summary["final"]
    # no force along x: the block's and the removed momentum add up to the start's; along y
    # gravity acts on the mass still in the mesh, which the momentum check follows (drift)
    assert final["momentum_x"] + removed["momentum"][0] == pytest.approx(0.3 * m0, rel=1e-12)
    assert removed["kinetic"] > 0 and summary["health"]["energy_ratio"] == pytest.approx(1.0, abs=1e-3)
    assert summary["health"]["momentum_drift"] < 1e-9
    if comm.rank == 0:
        with open(tmp_path / "energies.csv") as fh:
            rows = list(csv.DictReader(fh))
        assert float(rows[-1]["removed_mass"]) == pytest.approx(removed["mass"], rel=1e-14)
        assert float(rows[0]["removed_mass"]) == 0.0 and "removed_kinetic" in rows[0]
        assert json.loads((tmp_path / "summary.json").read_text())["removed"]["count"] == removed["count"]


def test_two_ranks_remove_what_one_rank_removes():
    world = run(falling_block(), progress=False)["removed"]
    alone = run(falling_block(MPI.COMM_SELF), progress=False)["removed"]
    assert world["count"] == alone["count"]
    assert world["mass"] == pytest.approx(alone["mass"], rel=1e-12)
    assert world["kinetic"] == pytest.approx(alone["kinetic"], rel=1e-9)


def test_the_numpy_and_the_compiled_step_remove_alike():
    a, b = falling_block(), falling_block()
    sa, sb = a.solver(), b.solver()
    sb.compiled = False
    for _ in range(3000):
        if sa.t >= 0.47:
            break
        dt = sa.step()
        sb.step(dt)
    assert sa.removed.count == sb.removed.count > 0
    assert sa.removed.mass == pytest.approx(sb.removed.mass, rel=1e-12)


def test_a_resumed_run_keeps_what_was_removed(tmp_path):
    """Fixed steps of 2^-10: the run to 0.25 (some particles removed by then, from 0.2) and its
    continuation to 0.35 take the steps of the uninterrupted run."""
    comm = MPI.COMM_WORLD
    base = comm.bcast(str(tmp_path), root=0)

    def block(t_end):
        scene = falling_block(t_end=t_end)
        scene.particles.x[:, 1] -= 0.75  # lower: the first rows leave before t = 0.25
        scene.particles.relocate()
        scene.dt = 2.0**-10
        return scene

    whole = run(block(0.35), base + "/whole", progress=False)
    part = run(block(0.25), base + "/part", progress=False, checkpoint_every=64)
    resumed = run(block(0.35), base + "/part", progress=False, resume=True)
    assert 0 < part["removed"]["count"] < resumed["removed"]["count"]
    assert resumed["removed"] == whole["removed"]
    for k in ("energy_ratio", "momentum_drift", "external_work"):  # the checks' state restored with it
        assert resumed["health"][k] == pytest.approx(whole["health"][k], rel=1e-9, abs=1e-12), k


def test_a_run_whose_particles_all_left_stops_saying_so():
    with pytest.raises(fempm.SimulationError, match=r"every particle has left the mesh \(\d+ removed, mass 250\)"):
        run(falling_block(t_end=0.7), progress=False)


def test_raise_is_the_default_and_bad_policies_are_named():
    scene = falling_block(outside="raise")
    with pytest.raises(fempm.OutsideMeshError, match=r"particle\(s\) lie outside the mesh"):
        run(scene, progress=False)
    with pytest.raises(ValueError, match=r"unknown option outside='drop'; expected one of raise, remove"):
        falling_block(outside="drop")
    mesh = dm.create_unit_square(MPI.COMM_WORLD, 2, 2)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    with pytest.raises(ValueError, match=r"unknown option outside='drop'"):
        ExplicitSolver(V, fempm.create_particles(mesh, 1), [LinearElastic(1.0, 0.3)], options=StepOptions(),
                       outside="drop")


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="command-line output on one rank")
def test_outside_from_the_command_line(tmp_path, capsys):
    from fempm.cli import main

    assert main(["run", "bar", "--cells", "4", "--t-end", "0.5", "--outside", "remove",
                 "--out", str(tmp_path / "run")]) == 0
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["removed"] == {"count": 0, "mass": 0.0, "kinetic": 0.0, "strain": 0.0, "momentum": []}
    assert main(["run", "bar", "--cells", "4", "--outside", "drop", "--out", str(tmp_path / "bad")]) == 2
    assert "option --outside expects one of raise, remove, got 'drop'" in capsys.readouterr().err
