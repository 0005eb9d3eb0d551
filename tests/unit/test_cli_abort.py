"""Under MPI, a command-line run that fails on one rank ends on every rank (no hang)."""

import subprocess
import sys
import time
from pathlib import Path

import pytest
from mpi4py import MPI


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="starts its own mpiexec")
def test_a_failure_on_one_rank_ends_both_ranks(tmp_path):
    """The output folder lies under a file: rank 0 fails creating it while rank 1 waits in a
    collective; the run must end at once with a non-zero exit and name the error."""
    blocker = tmp_path / "f"
    blocker.write_text("a file, not a folder")
    mpiexec = Path(sys.executable).with_name("mpiexec")
    cmd = [str(mpiexec), "-n", "2", sys.executable, "-m", "fempm", "run", "bar", "--cells", "8", "--t-end", "0.1",
           "--out", str(blocker / "out")]
    start = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert r.returncode != 0
    assert time.perf_counter() - start < 60
    assert "aborting all ranks" in r.stderr and "NotADirectoryError" in r.stderr
