"""Compiled per-particle kernels: the inner loops of a step, arrays in and arrays out.

Each kernel has a numpy reference implementation (``*_numpy``) that defines what it computes;
the compiled version (numba, ``*_numba``) is used when numba is installed and must agree with
the reference to round-off (``tests/kernels/test_kernels.py``). :data:`COMPILED`
(:mod:`fempm.kernels.choice`) tells which is in use; ``FEMPM_KERNELS=numpy`` in the environment selects the references.

Two modules work on whole passes rather than single operations: :mod:`fempm.kernels.shape`
(the degree-1 basis in closed form and the affine pull-back; basix and
:class:`fempm.meshes.geometry.CellGeometry` are their references) and :mod:`fempm.kernels.lumped`
(the passes of :class:`fempm.stepping.lumped.PointGrid`, whose reference is the generic
:meth:`fempm.stepping.ExplicitSolver.step`, ``tests/stepping/test_compiled_step.py``).
Processes that compile at the same time share numba's cache safely (:mod:`fempm.kernels.cache_lock`).
"""

from __future__ import annotations

from fempm.kernels import cache_lock
from fempm.kernels.choice import COMPILED
from fempm.kernels.g2p import g2p_point, velocity_and_gradient
from fempm.kernels.kinematics import deform, linear_elastic_stress, neo_hookean_stress
from fempm.kernels.p2g import nodal_forces

if COMPILED:
    cache_lock.install()  # before any kernel is compiled or loaded (several processes share the cache)

__all__ = ["COMPILED", "deform", "g2p_point", "linear_elastic_stress", "neo_hookean_stress", "nodal_forces",
           "velocity_and_gradient"]
