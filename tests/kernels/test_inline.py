"""The test run compiles the kernels with their helpers called (``FEMPM_NUMBA_INLINE=never``,
scripts/run-tests: a third of the compile time); what ships inlines them
(:data:`fempm.kernels.choice.INLINE`). Here a few of the suite's comparisons with the numpy
references run again with the shipped kernels, in a process of their own: the planar, solid,
sample (CPDI2) and affine (APIC) passes, the consistent mass and FMPM."""

import os
import subprocess
import sys
from pathlib import Path

import pytest
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = [
    "tests/stepping/test_compiled_step.py::test_compiled_step_equals_the_generic_step[triangle-MUSL-consistent]",
    "tests/stepping/test_compiled_step.py::test_compiled_step_equals_the_generic_step[hexahedron-MUSL-fmpm2]",
    "tests/stepping/test_domain_step.py::test_domain_passes_equal_the_numpy_step[triangle-MUSL-cpdi2]",
    "tests/transfer/test_transfers.py::test_an_affine_field_survives_p2g_then_g2p[triangle-apic-lumped-compiled]",
]


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="starts its own process")
def test_the_shipped_inlined_kernels_equal_the_numpy_references():
    env = {k: v for k, v in os.environ.items() if k not in ("FEMPM_NUMBA_INLINE", "PYTEST_XDIST_WORKER")}
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-m", "slow or not slow",
                        *SHIPPED], cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    assert f"{len(SHIPPED)} passed" in r.stdout, r.stdout[-2000:]


def test_the_inline_option_is_checked():
    r = subprocess.run([sys.executable, "-c", "import fempm"], env={**os.environ, "FEMPM_NUMBA_INLINE": "sometimes"},
                       capture_output=True, text=True, timeout=300)
    assert r.returncode != 0 and "FEMPM_NUMBA_INLINE='sometimes': expected one of always, never" in r.stderr
