"""Compiled per-particle kernels: the inner loops of a step, arrays in and arrays out.

Each kernel has a numpy reference implementation (``*_numpy``) that defines what it computes;
the compiled version (numba, ``*_numba``) is used when numba is installed and must agree with
the reference to round-off (``tests/unit/test_kernels.py``). :data:`COMPILED` tells which is
in use; ``FEMPM_KERNELS=numpy`` in the environment selects the references.
"""

from __future__ import annotations

import os

try:
    import numba  # noqa: F401

    COMPILED = os.environ.get("FEMPM_KERNELS", "numba") != "numpy"
except ImportError:  # the numpy references
    COMPILED = False

from fempm.kernels.g2p import g2p_point, velocity_and_gradient  # noqa: E402
from fempm.kernels.kinematics import deform, linear_elastic_stress, neo_hookean_stress  # noqa: E402
from fempm.kernels.p2g import nodal_forces  # noqa: E402

__all__ = ["COMPILED", "deform", "g2p_point", "linear_elastic_stress", "neo_hookean_stress", "nodal_forces",
           "velocity_and_gradient"]
