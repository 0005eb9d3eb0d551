"""FMPM(k) (fempm.transfer.fmpm): k = 1 is the lumped map, the grid values approach the consistent ones
as k grows, every order conserves momentum, and the loop runs with it."""

import dolfinx.fem as fem
import dolfinx.mesh as dm
import numpy as np
import pytest
from mpi4py import MPI

import fempm
from fempm.transfer.mass_models import FMPM, Consistent, Lumped, mass_model
from fempm.scene import run
from fempm.scenes import two_disks, vibrating_bar

pytestmark = [pytest.mark.parallel,  # also under mpiexec -n 2 (scripts/run-tests)
              pytest.mark.xdist_group("test_fmpm")]  # one worker computes its module fixtures

comm = MPI.COMM_WORLD


@pytest.fixture(scope="module", params=["quadrilateral", "triangle"])
def setup(request):
    mesh = dm.create_unit_square(comm, 6, 6, getattr(dm.CellType, request.param))
    p = fempm.create_particles(mesh, 4, jitter=0.6, seed=3)
    V = fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    f = np.c_[np.sin(3 * p.x[:, 0]), p.x[:, 1] ** 2 - p.x[:, 0]]
    return V, p, f


def _dist(a, b):
    return comm.allreduce(float(np.abs(a - b).max(initial=0.0)), op=MPI.MAX)


def test_fmpm1_is_lumped_and_fmpm_approaches_consistent(setup):
    V, p, f = setup
    lumped = fempm.project(V, p, f, mass="lumped").x.array
    consistent = fempm.project(V, p, f, mass="consistent").x.array
    assert _dist(fempm.project(V, p, f, mass="fmpm1").x.array, lumped) < 1e-14
    dist = [_dist(fempm.project(V, p, f, mass=f"fmpm{k}").x.array, consistent) for k in range(1, 11)]
    assert np.all(np.diff(dist) < 0), dist  # monotone: the error (1 - mu)^k shrinks for mu in (0, 1]
    assert dist[9] < 0.25 * dist[0]


@pytest.mark.parametrize("k", [1, 2, 5, 10])
def test_every_order_conserves_momentum(setup, k):
    V, p, f = setup
    proj = fempm.Projector(V, p, mass="fmpm", fmpm_order=k)
    total = proj.grid_total(proj.project(f))
    assert np.abs(total - comm.allreduce(p.mass @ f)).max() < 1e-13 * comm.allreduce(p.mass.sum())


def test_mass_option_parsing():
    assert mass_model("fmpm3") == FMPM(3) == mass_model("fmpm(3)") == mass_model("fmpm", 3)
    assert mass_model("fmpm").label == "fmpm5" and mass_model("lumped") == Lumped()
    assert mass_model("consistent") == Consistent() and mass_model(FMPM(2)) == FMPM(2)
    assert [m.stable_factor(lambda: 0.5) for m in (Lumped(), Consistent(), FMPM(4))] == [1.0, np.sqrt(0.4), 0.5]
    for bad in ("fmpm0", "fmpm11", "fmpmx", "full"):
        with pytest.raises(ValueError):
            mass_model(bad)


@pytest.mark.slow  # 19 s cold; the default run: FMPM's compiled step against the numpy one (test_compiled_step.py)
def test_loop_fmpm1_equals_lumped_and_fmpm_runs_stably():
    runs = {}
    for mass in ("lumped", "fmpm1"):
        scene = vibrating_bar(cells=8, t_end=5.0, mass=mass, comm=comm)
        scene.dt = 0.1
        runs[mass] = run(scene, None, progress=False)["history"]
    a, b = (np.array([[r["total"], r["momentum_x"]] for r in runs[m]]) for m in ("lumped", "fmpm1"))
    assert np.abs(a - b).max() < 1e-12 * np.abs(a).max()  # round-off: m^-1 b against b / m
    s = run(two_disks(cells=10, t_end=2.5, mass="fmpm5", frames=0, comm=comm), None, progress=False)
    assert s["status"] == "completed" and 0.7 < s["health"]["energy_ratio"] < 1.2
    assert abs(s["final"]["momentum_x"]) < 1e-12  # the disks' total momentum is zero
