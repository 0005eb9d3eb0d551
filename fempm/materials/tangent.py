r"""The stress after a deformation increment, and its tangent: what an implicit step asks of a law.

Within an implicit step the particles sit where the step began (configuration :math:`x_n`);
Newton's method iterates on the grid's displacement increment :math:`\Delta u`, whose gradient
at a particle,

.. math::
    G = \frac{\partial \Delta u}{\partial x_n}, \qquad \Delta F = I + G, \qquad F = \Delta F\, F_n,

gives the law its deformation: an elastic law the new :math:`F`, a hypoelastic one the velocity
gradient over the step, :math:`L = G / \Delta t` (:func:`stress_after`, the law's own ``stress``
with the step's :math:`\Delta t`; a rate-independent law's stress depends on :math:`L\,\Delta t = G`
alone, a rate-dependent one's, :class:`MuI`, on the rate too). The tangent is

.. math::
    \mathbb{D}_{ijkl} = \frac{\partial \sigma_{ij}}{\partial G_{kl}},

(n, d, d, d, d) arrays, from the law's ``tangent(F, G, sigma, state)`` (:class:`LinearElastic`,
:class:`NeoHookean`, and the algorithmic tangents of the return mappings of :class:`VonMises`,
:class:`DruckerPrager` and, with the step's ``dt`` as a keyword (``rate_dependent`` laws),
:class:`MuI`) or, for a law without one, by central differences of
:func:`stress_after` when asked for by name (:func:`tangent_of` with
``finite_difference=True``).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from fempm.kernels.implicit import increment_determinants
from fempm.kernels.kinematics import deform

__all__ = ["FD_STEP", "deformed", "finite_difference_tangent", "rate_dependent", "stress_after", "tangent_fixed_in_step",
           "tangent_of"]

#: the step of the finite-difference tangent, relative to 1 (G is dimensionless)
FD_STEP = 1e-6


def deformed(F: npt.NDArray, G: npt.NDArray) -> npt.NDArray:
    r""":math:`F = (I + G) F_n` (n, d, d): :func:`fempm.kernels.kinematics.deform` with
    :math:`\Delta t\, L = G` (compiled)."""
    return deform(np.ascontiguousarray(F), np.ascontiguousarray(G), 1.0)[0]


def rate_dependent(law) -> bool:
    """Whether ``law``'s stress depends on the rate, not only on the increment (its class
    attribute ``rate_dependent``; False where it has none)."""
    return bool(getattr(law, "rate_dependent", False))


def tangent_fixed_in_step(law) -> bool:
    """Whether ``law``'s tangent is the same at every increment of a step: the class attribute
    ``tangent_fixed_in_step`` of the class whose ``tangent`` the law takes (a law linear in F,
    whose tangent depends on :math:`F_n` alone; a subclass with a ``tangent`` of its own does not
    inherit it); False where it has none."""
    owner = next((c for c in type(law).__mro__ if "tangent" in vars(c)), None)
    return owner is not None and bool(vars(owner).get("tangent_fixed_in_step", False))


def stress_after(law, F: npt.NDArray, G: npt.NDArray, sigma: npt.NDArray, rho: npt.NDArray,
                 state: dict | None = None, dt: float = 1.0) -> tuple[npt.NDArray, dict]:
    r"""The Cauchy stress (n, d, d) after the increment of displacement gradient ``G`` over a
    step ``dt`` and the law's internal variables after it: ``law.stress`` with
    :math:`F = (I + G) F_n`, :math:`L = G / \Delta t`, ``dt`` and the density
    :math:`\rho_n / \det(I + G)`.

    Args:
        law: A material law (:class:`fempm.materials.base.Material`).
        F: The deformation gradients at the step's start, :math:`F_n` (n, d, d).
        G: The increments' displacement gradients (n, d, d).
        sigma: The stresses at the step's start (n, d, d).
        rho: The densities at the step's start (n,).
        state: The law's internal variables at the step's start (left as they are).
        dt: The step's length (> 0; what a rate-independent law's stress does not depend on).

    Returns:
        (the stresses, a new dict of the internal variables).
    """
    rho_new = rho / increment_determinants(np.ascontiguousarray(G))
    L = G / dt
    if law.history:
        new = dict(state or {})
        return np.asarray(law.stress(deformed(F, G), L, sigma, dt, rho_new, new)), new
    return np.asarray(law.stress(deformed(F, G), L, sigma, dt, rho_new)), {}


def finite_difference_tangent(law, F: npt.NDArray, G: npt.NDArray, sigma: npt.NDArray, rho: npt.NDArray,
                              state: dict | None = None, step: float = FD_STEP, dt: float = 1.0) -> npt.NDArray:
    r"""The tangent :math:`\partial \sigma_{ij} / \partial G_{kl}` (n, d, d, d, d) by central
    differences of :func:`stress_after` (:math:`2 d^2` stress updates; the error is
    :math:`O(h^2)` where the law is smooth, and the rounding error about :math:`10^{-16}/h`
    relative)."""
    n, d = F.shape[0], F.shape[1]
    D = np.empty((n, d, d, d, d))
    for k in range(d):
        for m in range(d):
            E = np.zeros((d, d))
            E[k, m] = step
            plus = stress_after(law, F, G + E, sigma, rho, state, dt)[0]
            minus = stress_after(law, F, G - E, sigma, rho, state, dt)[0]
            D[:, :, :, k, m] = (plus - minus) / (2.0 * step)
    return D


def tangent_of(law, F: npt.NDArray, G: npt.NDArray, sigma: npt.NDArray, rho: npt.NDArray,
               state: dict | None = None, *, finite_difference: bool = False, dt: float = 1.0) -> npt.NDArray:
    r"""The law's tangent :math:`\partial \sigma / \partial G` (n, d, d, d, d) over a step
    ``dt``: its own ``tangent(F, G, sigma, state)`` (``tangent(F, G, sigma, state, dt=dt)`` for
    a :func:`rate_dependent` law), or with ``finite_difference`` the central differences of
    :func:`stress_after` (for a law without one; slower by :math:`2 d^2` stress updates).

    Raises:
        TypeError: The law has no ``tangent`` and ``finite_difference`` is False.
    """
    if finite_difference:
        return finite_difference_tangent(law, F, G, sigma, rho, state, dt=dt)
    if not hasattr(law, "tangent"):
        raise TypeError(f"{type(law).__name__} has no tangent(F, G, sigma, state): an implicit step needs "
                        "dsigma/dG; give the law one, or ask for the finite-difference tangent by name "
                        "(finite_difference=True)")
    rate = {"dt": dt} if rate_dependent(law) else {}
    D = np.asarray(law.tangent(F, G, sigma, state if law.history else None, **rate))
    n, d = F.shape[0], F.shape[1]
    if D.shape != (n, d, d, d, d):
        raise ValueError(f"{type(law).__name__}.tangent returned an array of shape {D.shape}; expected "
                         f"{(n, d, d, d, d)}")
    return D
