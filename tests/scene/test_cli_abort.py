"""Under MPI, a command-line run that fails on one rank ends on every rank (no hang)."""

import subprocess
import sys
import time
from pathlib import Path

import pytest
from mpi4py import MPI


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="starts its own mpiexec")
def test_an_output_folder_under_a_file_ends_both_ranks(tmp_path):
    """The output folder lies under a file: rank 0 cannot create it; every rank must end at
    once with exit code 2 and one line naming the problem (fempm.io.make_folder)."""
    blocker = tmp_path / "f"
    blocker.write_text("a file, not a folder")
    mpiexec = Path(sys.executable).with_name("mpiexec")
    cmd = [str(mpiexec), "-n", "2", sys.executable, "-m", "fempm", "run", "bar", "--cells", "8", "--t-end", "0.1",
           "--out", str(blocker / "out")]
    start = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert time.perf_counter() - start < 60
    assert r.returncode == 2  # checked on every rank before the run: a usage error
    assert "cannot write the output folder" in r.stderr and "Not a directory" in r.stderr
    assert "Traceback" not in r.stderr


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="starts its own mpiexec")
def test_an_exception_on_one_rank_aborts_every_rank():
    """An error raised on rank 0 only, while rank 1 waits in a collective call: the command
    line's guard (fempm.abort.abort_on_error) ends both ranks with a non-zero exit."""
    script = ("from mpi4py import MPI\n"
              "from fempm.abort import abort_on_error\n"
              "with abort_on_error():\n"
              "    if MPI.COMM_WORLD.rank == 0:\n"
              "        raise RuntimeError('rank-local failure')\n"
              "    MPI.COMM_WORLD.Barrier()\n")
    mpiexec = Path(sys.executable).with_name("mpiexec")
    start = time.perf_counter()
    r = subprocess.run([str(mpiexec), "-n", "2", sys.executable, "-c", script], capture_output=True, text=True,
                       timeout=120)
    assert time.perf_counter() - start < 60
    assert r.returncode != 0
    assert "rank 0 of 2 failed; aborting all ranks" in r.stderr and "rank-local failure" in r.stderr


MATERIAL_SCRIPT = """
import dataclasses
from mpi4py import MPI
from fempm.abort import abort_on_error
from fempm.materials import LinearElastic
from fempm.scene import run
from fempm.scenes import two_disks


@dataclasses.dataclass(frozen=True)
class Failing(LinearElastic):  # a user law without a compiled kernel that fails on rank 0 at step 3
    def stress(self, F, L, sigma, dt, rho):
        if MPI.COMM_WORLD.rank == 0 and Failing.calls == 3:
            raise RuntimeError("the law failed on rank 0")
        Failing.calls += 1
        return super().stress(F, L, sigma, dt, rho)


Failing.calls = 0
scene = two_disks(cells=10, t_end=0.5)
scene = dataclasses.replace(scene, materials=[Failing(1000.0, 0.3)])
with abort_on_error():
    run(scene, progress=False)
"""


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="starts its own mpiexec")
def test_a_material_raising_on_one_rank_ends_both_ranks(tmp_path):
    """Rank 1 waits in the step's collective calls while rank 0's law raises: a script under
    fempm.abort.abort_on_error ends both ranks with a non-zero exit and the message."""
    script = tmp_path / "failing.py"
    script.write_text(MATERIAL_SCRIPT)
    mpiexec = Path(sys.executable).with_name("mpiexec")
    start = time.perf_counter()
    r = subprocess.run([str(mpiexec), "-n", "2", sys.executable, str(script)], capture_output=True, text=True,
                       timeout=120)
    assert time.perf_counter() - start < 60
    assert r.returncode != 0
    assert "rank 0 of 2 failed; aborting all ranks" in r.stderr and "the law failed on rank 0" in r.stderr, \
        (r.returncode, r.stdout[-2000:], r.stderr[-2000:])
