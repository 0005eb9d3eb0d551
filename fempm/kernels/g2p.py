r"""Grid-to-particle kernels for point particles (one cell per particle).

With the particle's dofs :math:`i_a`, values :math:`N_a = S[p, a]` and gradients
:math:`\nabla N_a = G[p, a]`:

.. math::
    \bar v_p = \sum_a N_a v^+_{i_a}, \qquad
    v_p^+ = \alpha \Big(v_p + \sum_a N_a (v^+_{i_a} - v_{i_a})\Big) + (1 - \alpha)\, \bar v_p,
    \qquad L_p = \sum_a v^+_{i_a} \otimes \nabla N_a .

:func:`g2p_point` returns all three in one pass over the particles (USL, USF);
:func:`interpolate` the values :math:`\sum_a N_a f_{i_a}` of any nodal field (the basis's ``gather``);
:func:`velocity_and_gradient` returns :math:`\bar v_p` and :math:`L_p` of one grid velocity
(MUSL's re-mapped one).
"""

from __future__ import annotations

import functools

import numpy as np
import numpy.typing as npt

from fempm.kernels.choice import pick

__all__ = ["g2p_point", "g2p_point_numpy", "interpolate", "interpolate_numpy", "velocity_and_gradient",
           "velocity_and_gradient_numpy"]


def g2p_point_numpy(dofs, S, G, v_new, v_old, vp, flip):
    """Reference: (v_p^+, grid velocity at the particles, L_p)."""
    vn, dv = v_new[dofs], (v_new - v_old)[dofs]  # (n, k, d)
    vgrid = np.einsum("na,nad->nd", S, vn)
    blended = flip * (vp + np.einsum("na,nad->nd", S, dv)) + (1.0 - flip) * vgrid
    L = np.einsum("nai,naj->nij", vn, G)
    return blended, vgrid, L


def velocity_and_gradient_numpy(dofs, S, G, v):
    """Reference: (grid velocity at the particles, L_p)."""
    vn = v[dofs]
    return np.einsum("na,nad->nd", S, vn), np.einsum("nai,naj->nij", vn, G)


def interpolate_numpy(dofs, S, nodal):
    return np.einsum("na,nak->nk", S, nodal[dofs])


try:
    from numba import njit

    @njit(cache=True)
    def _g2p(dofs, S, G, v_new, v_old, vp, flip, blended, vgrid, L):  # pragma: no cover - compiled
        n, k = S.shape
        d = vp.shape[1]
        for p in range(n):
            for c in range(d):
                vg = 0.0
                dv = 0.0
                for a in range(k):
                    i = dofs[p, a]
                    vg += S[p, a] * v_new[i, c]
                    dv += S[p, a] * (v_new[i, c] - v_old[i, c])
                    for e in range(d):
                        L[p, c, e] += v_new[i, c] * G[p, a, e]
                vgrid[p, c] = vg
                blended[p, c] = flip * (vp[p, c] + dv) + (1.0 - flip) * vg

    @njit(cache=True)
    def _interp(dofs, S, G, v, vgrid, L):  # pragma: no cover - compiled
        n, k = S.shape
        d = v.shape[1]
        for p in range(n):
            for c in range(d):
                vg = 0.0
                for a in range(k):
                    i = dofs[p, a]
                    vg += S[p, a] * v[i, c]
                    for e in range(d):
                        L[p, c, e] += v[i, c] * G[p, a, e]
                vgrid[p, c] = vg

    def g2p_point_numba(dofs, S, G, v_new, v_old, vp, flip):
        n, d = vp.shape
        blended, vgrid, L = np.empty((n, d)), np.empty((n, d)), np.zeros((n, d, G.shape[2]))
        _g2p(dofs, S, G, np.ascontiguousarray(v_new), np.ascontiguousarray(v_old), np.ascontiguousarray(vp),
             float(flip), blended, vgrid, L)
        return blended, vgrid, L

    @functools.cache
    def _interpolate(k: int):
        """:func:`interpolate` of ``k`` dofs a particle (a compile-time loop; the components' too
        would gain another 20 % for many more variants to compile)."""

        @njit(cache=True)
        def interpolate(dofs, S, nodal):  # pragma: no cover - compiled
            n, c = S.shape[0], nodal.shape[1]
            out = np.empty((n, c))
            for p in range(n):
                for r in range(c):
                    s = 0.0
                    for a in range(k):
                        s += S[p, a] * nodal[dofs[p, a], r]
                    out[p, r] = s
            return out

        return interpolate

    def interpolate_numba(dofs, S, nodal):
        if nodal.dtype != np.float64 or nodal.ndim != 2:  # (what the kernel is compiled for)
            return interpolate_numpy(dofs, S, nodal)
        return _interpolate(S.shape[1])(np.ascontiguousarray(dofs), np.ascontiguousarray(S), np.ascontiguousarray(nodal))

    def velocity_and_gradient_numba(dofs, S, G, v):
        n, d = len(S), v.shape[1]
        vgrid, L = np.empty((n, d)), np.zeros((n, d, G.shape[2]))
        _interp(dofs, S, G, np.ascontiguousarray(v), vgrid, L)
        return vgrid, L
except ImportError:  # pragma: no cover - numba is a dependency; the references stand in
    g2p_point_numba = g2p_point_numpy
    interpolate_numba = interpolate_numpy
    velocity_and_gradient_numba = velocity_and_gradient_numpy


def g2p_point(dofs: npt.NDArray, S: npt.NDArray, G: npt.NDArray, v_new: npt.NDArray, v_old: npt.NDArray,
              vp: npt.NDArray, flip: float) -> tuple[npt.NDArray, npt.NDArray, npt.NDArray]:
    """(v_p^+, the grid velocity at the particles, L_p) for nodal (ndofs, d) ``v_new``/``v_old``
    with ghosts up to date, particle velocities ``vp`` (n, d) and the FLIP fraction ``flip``."""
    return pick(g2p_point_numba, g2p_point_numpy)(dofs, S, G, v_new, v_old, vp, flip)


def velocity_and_gradient(dofs: npt.NDArray, S: npt.NDArray, G: npt.NDArray,
                          v: npt.NDArray) -> tuple[npt.NDArray, npt.NDArray]:
    """(the grid velocity at the particles, L_p) of nodal (ndofs, d) ``v``, ghosts up to date."""
    return pick(velocity_and_gradient_numba, velocity_and_gradient_numpy)(dofs, S, G, v)


def interpolate(dofs: npt.NDArray, S: npt.NDArray, nodal: npt.NDArray) -> npt.NDArray:
    r""":math:`f_p = \sum_a S[p, a]\, F_{d(p,a)}` (n, c) of nodal (ndofs, c) data (ghosts up to date)."""
    return pick(interpolate_numba, interpolate_numpy)(dofs, S, nodal)
