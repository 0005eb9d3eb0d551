"""The implicit step's iterative linear solver through the ``fempm_implicit_`` options: CG with
PETSc's algebraic multigrid (GAMG) instead of the default MUMPS LU, on a 3D block under its own
weight; the same displacements as LU, and (``slow``) a problem of 1e6 dofs on 2 ranks."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from fempm.boundary import fixed
from fempm.materials import LinearElastic
from fempm.meshes import structured as dm
from fempm.particles.seeding import create_particles
from fempm.scene import Scene, run
from fempm.stepping import Loads, StepOptions

comm = MPI.COMM_WORLD
GAMG = {"ksp_type": "cg", "pc_type": "gamg", "ksp_rtol": 1e-10, "snes_rtol": 1e-10}


def block(n: int, comm=comm) -> Scene:
    """A unit cube of n^3 x 6 tetrahedra, one particle each, fixed at y = 0, under gravity, one
    quasi-static step."""
    mesh = dm.create_box(comm, [[0, 0, 0], [1, 1, 1]], [n, n, n], dm.CellType.tetrahedron)
    p = create_particles(mesh, 1, density=1.0)
    return Scene(name="block3d", mesh=mesh, particles=p, materials=[LinearElastic(1e3, 0.3)], t_end=1.0, dt=1.0,
                 bcs=lambda V: [fixed(V, lambda x: np.isclose(x[1], 0.0))], loads=Loads(body_force=(0.0, -1.0, 0.0)),
                 options=StepOptions(integrator="implicit", dynamics="quasi-static", load_ramp=1.0), frames=0)


def displacements(summary) -> np.ndarray:
    p = summary["solver"].particles
    ids = np.concatenate(comm.allgather(p.ids))
    u = np.concatenate(comm.allgather(p.x - p.fields["X0"]))
    return u[np.argsort(ids)]


@pytest.fixture
def options():
    """Set PETSc options under the prefix for one test, removed afterwards."""
    db, given = PETSc.Options(), []

    def give(values: dict):
        for k, v in values.items():
            db["fempm_implicit_" + k] = v
            given.append("fempm_implicit_" + k)

    yield give
    for k in given:
        db.delValue(k)


@pytest.mark.parallel
def test_cg_with_algebraic_multigrid_gives_the_lu_answer(options):
    lu = displacements(run(block(8), None, progress=False))
    options(GAMG)
    summary = run(block(8), None, progress=False)
    assert summary["solver"].implicit.newton.snes.getKSP().getType() == "cg"
    assert summary["solver"].implicit.newton.snes.getKSP().getPC().getType() == "gamg"
    gamg = displacements(summary)
    assert np.abs(gamg - lu).max() < 1e-8 * np.abs(lu).max() and np.abs(lu).max() > 4e-4


SCRIPT = """
import sys
import fempm  # (before petsc4py: the wheel's libraries)
from petsc4py import PETSc
from mpi4py import MPI
sys.path.insert(0, {tests!r})
from test_iterative_solver import GAMG, block
from fempm.scene import run
for k, v in GAMG.items():
    PETSc.Options()["fempm_implicit_" + k] = v
scene = block(69)
dofs = 3 * scene.space().dofmap.index_map.size_global
summary = run(scene, None, progress=False)
s = summary["solver"]
uy = MPI.COMM_WORLD.allreduce(float((s.particles.x[:, 1] - s.particles.fields["X0"][:, 1]).min(initial=0)), op=MPI.MIN)
if MPI.COMM_WORLD.rank == 0:
    print("RESULT", dofs, summary["status"], s.implicit.newton.snes.getKSP().getPC().getType(), uy)
"""


@pytest.mark.slow
@pytest.mark.skipif(comm.size > 1, reason="starts its own 2 ranks")
def test_a_million_dofs_in_3d_on_two_ranks_with_algebraic_multigrid(tmp_path):
    """1,029,000 dofs (70^3 vertices, 1,971,054 particles), CG + GAMG on 2 ranks: 3 Newton
    iterations, about 90 s and 7 GB a rank on this machine; the lowest displacement on the
    sequence n = 12, 40, 69 (-4.8514e-4, -4.9076e-4, -4.9141e-4) converges."""
    script = tmp_path / "million.py"
    script.write_text(SCRIPT.format(tests=str(Path(__file__).parent)))
    mpiexec = Path(sys.executable).with_name("mpiexec")
    r = subprocess.run([str(mpiexec), "-n", "2", sys.executable, str(script)], capture_output=True, text=True,
                       timeout=1200)
    assert r.returncode == 0, r.stderr[-3000:]
    _, dofs, status, pc, uy = [line for line in r.stdout.splitlines() if line.startswith("RESULT")][0].split()
    assert int(dofs) >= 1_000_000 and status == "completed" and pc == "gamg"
    assert float(uy) == pytest.approx(-4.9141e-4, rel=2e-4)


@pytest.mark.parallel
def test_petsc_options_on_the_command_line_are_the_runs_and_its_resumes(tmp_path, monkeypatch):
    """``-fempm_implicit_pc_type gamg`` after the scene options: the run's Newton takes it, the
    checkpoint keeps it for ``resume``, and it is gone from the options database afterwards."""
    import json

    from fempm.cli import main
    from fempm.implicit.newton import Newton
    from fempm.run_options import petsc_options

    assert petsc_options(["--cells", "4", "-a_b", "-1.5", "-flag", "-c_d", "x", "--dim", "3"]) == (
        {"a_b": "-1.5", "flag": "", "c_d": "x"}, ["--cells", "4", "--dim", "3"])
    seen = []
    original = Newton.__init__

    def spy(self, *args, **kwargs):
        original(self, *args, **kwargs)
        seen.append((self.snes.getKSP().getType(), self.snes.getKSP().getPC().getType()))

    monkeypatch.setattr(Newton, "__init__", spy)
    out = Path(comm.bcast(str(tmp_path / "c") if comm.rank == 0 else None))
    args = ["run", "compaction", "--dim", "3", "--cells", "4", "--frames", "0", "--out", str(out),
            "--checkpoint-every", "2", "-fempm_implicit_ksp_type", "cg", "-fempm_implicit_pc_type", "gamg"]
    assert main(args) == 0
    assert seen and all(kinds == ("cg", "gamg") for kinds in seen)
    assert not PETSc.Options().hasName("fempm_implicit_pc_type")
    checkpoint = json.loads((out / "checkpoint" / "manifest.json").read_text())
    assert checkpoint["rebuild"]["petsc"] == {"fempm_implicit_ksp_type": "cg", "fempm_implicit_pc_type": "gamg"}
    seen.clear()
    assert main(["resume", str(out), "--t-end", "2"]) == 0
    assert seen and all(kinds == ("cg", "gamg") for kinds in seen)
    assert not PETSc.Options().hasName("fempm_implicit_pc_type")
