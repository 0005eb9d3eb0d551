"""A run under `mpiexec -n 2` that fails on one rank only ends every rank within seconds, with
the error and the failing rank printed, a non-zero exit and a summary.json of status "failed"
(fempm.scene.run with fempm.abort.FailureAgreement): a law raising on rank 1, a Scene.watch
raising on rank 1, rank 1's particle frame failing to write; from a script under
abort_on_error and from the command line (fempm.cli.main). Before, each of them hung: the
failing rank went on to the final frame's collective writes alone."""

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mpi4py import MPI

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="starts its own mpiexec")

#: what makes rank 1 fail, armed at step 4 (written into the script before the run)
FAILURES = {
    "law": """
import dataclasses
import fempm.scenes
from fempm.materials import LinearElastic
@dataclasses.dataclass(frozen=True)
class Failing(LinearElastic):  # a user law (no compiled kernel) that fails on rank 1
    def stress(self, F, L, sigma, dt, rho):
        if MPI.COMM_WORLD.rank == 1 and armed():
            raise RuntimeError("the law failed on rank 1")
        return super().stress(F, L, sigma, dt, rho)
_build = fempm.scenes.SCENES["disks"]
@functools.wraps(_build)  # the command line reads the builder's options from its signature
def two_disks(**kw):
    return dataclasses.replace(_build(**kw), materials=[Failing(1000.0, 0.3)])
fempm.scenes.SCENES["disks"] = two_disks
""",
    "watch": """
import fempm.scenes
_build = fempm.scenes.SCENES["disks"]
@functools.wraps(_build)  # the command line reads the builder's options from its signature
def two_disks(**kw):
    scene = _build(**kw)
    def watch(solver):
        if MPI.COMM_WORLD.rank == 1 and armed():
            raise RuntimeError("the watch failed on rank 1")
    scene.watch = watch
    return scene
fempm.scenes.SCENES["disks"] = two_disks
""",
    "frame": """
import fempm.io.vtkhdf
_fill = fempm.io.vtkhdf._fill
def fill(path, *args, **kw):  # rank 1's rows of a particle frame
    if MPI.COMM_WORLD.rank == 1 and armed() and "particles_" in str(path):
        raise PermissionError(13, "Permission denied", str(path))  # as in a read-only folder
    return _fill(path, *args, **kw)
fempm.io.vtkhdf._fill = fill
""",
}

PREAMBLE = """
import functools, sys, time
from mpi4py import MPI
import fempm
OUT, STAMP = sys.argv[1], sys.argv[2]
calls = [0]
def armed():  # true from the 4th call on, when the stamp is written (the failure's time)
    calls[0] += 1
    if calls[0] >= 4:
        open(STAMP, "a").write(repr(time.time()) + "\\n")
        return True
    return False
"""

SCRIPT = """
from fempm.abort import abort_on_error
from fempm.scene import run
from fempm.scenes import SCENES
with abort_on_error():
    run(SCENES["disks"](cells=10, t_end=0.5, frames=50), OUT, progress=False)
"""

CLI = """
from fempm.cli import main
sys.exit(main(["run", "disks", "--cells", "10", "--t-end", "0.5", "--frames", "50", "--out", OUT]))
"""


@pytest.mark.parametrize("entry", ["script", "cli"])
@pytest.mark.parametrize("failure", sorted(FAILURES))
def test_a_failure_on_one_rank_ends_every_rank(tmp_path, failure, entry):
    script = tmp_path / "failing.py"
    script.write_text(PREAMBLE + FAILURES[failure] + (SCRIPT if entry == "script" else CLI))
    out, stamp = tmp_path / "out", tmp_path / "failed-at"
    mpiexec = Path(sys.executable).with_name("mpiexec")
    r = subprocess.run([str(mpiexec), "-n", "2", sys.executable, str(script), str(out), str(stamp)],
                       capture_output=True, text=True, timeout=120)
    ended = time.time()
    assert r.returncode != 0, r.stderr[-3000:]
    assert stamp.exists(), r.stderr[-3000:]  # it did fail where armed
    assert ended - float(stamp.read_text().split()[0]) < 10.0  # every rank ended within 10 s of the failure
    assert "rank 1" in r.stderr and ("failed on rank 1" in r.stderr or "Permission denied" in r.stderr), r.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed" and "rank 1" in summary["health"]["error"]
    assert summary["steps"] >= 1 and summary["scene"] == "two_disks"


BARE = {
    "particles": """
import numpy as np
import dolfinx.mesh as dm
mesh = dm.create_unit_square(MPI.COMM_WORLD, 4, 4)
n = 5
mass = np.ones(n + (1 if MPI.COMM_WORLD.rank == 1 else 0))  # one mass too many on rank 1 only
try:
    fempm.Particles(mesh, np.full((n, 2), 0.5), mass, np.ones(n))
except Exception as e:
    open(f"{sys.argv[1]}.{MPI.COMM_WORLD.rank}", "w").write(f"raised {type(e).__name__}: {e}")
""",
    "step": """
import dataclasses
import numpy as np
from fempm.materials import LinearElastic
from fempm.scenes import two_disks
@dataclasses.dataclass(frozen=True)
class Failing(LinearElastic):  # a user law (no compiled kernel) that fails on rank 1
    def stress(self, F, L, sigma, dt, rho):
        if MPI.COMM_WORLD.rank == 1:
            raise RuntimeError("the law failed on rank 1")
        return super().stress(F, L, sigma, dt, rho)
scene = two_disks(cells=10)
scene.materials = [Failing(1000.0, 0.3)]
solver = scene.solver()
try:
    solver.step()
except Exception as e:
    open(f"{sys.argv[1]}.{MPI.COMM_WORLD.rank}", "w").write(f"raised {type(e).__name__}: {e}")
""",
}


@pytest.mark.parametrize("case", sorted(BARE))
def test_an_error_on_one_rank_is_raised_on_every_rank(tmp_path, case):
    """Outside fempm.scene.run and without abort_on_error (they hung): a Particles array of the
    wrong length on rank 1 only, and a law raising on rank 1 in a bare solver.step(): every rank
    raises, naming the error (the constructor's checks and the step's law calls are collective)."""
    script = tmp_path / "bare.py"
    script.write_text("import sys\nfrom mpi4py import MPI\nimport fempm\n" + BARE[case])
    mpiexec = Path(sys.executable).with_name("mpiexec")
    said = tmp_path / "raised"
    r = subprocess.run([str(mpiexec), "-n", "2", sys.executable, str(script), str(said)], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-3000:]
    lines = [Path(f"{said}.{rank}").read_text() for rank in (0, 1)]  # (a rank that hung would have no file)
    expected = "mass has shape (6,) for 5 particles" if case == "particles" else "the law failed on rank 1"
    assert all(line.startswith("raised ") and expected in line for line in lines), lines
    assert "RankError: rank 1 of 2 failed" in lines[0], lines
