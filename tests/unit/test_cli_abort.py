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
    line's guard (fempm.cli._abort_on_error) ends both ranks with a non-zero exit."""
    script = ("from mpi4py import MPI\n"
              "import fempm.cli\n"
              "with fempm.cli._abort_on_error():\n"
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
