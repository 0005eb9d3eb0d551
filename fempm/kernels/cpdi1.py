r"""CPDI1's samples, compiled: the corners of each particle's parallelogram (parallelepiped)
domain, located in the cells, and their weights computed where the passes use them.

A particle :math:`p` at :math:`x_p` with deformation gradient :math:`F_p` and half-widths
:math:`\ell_p` has the :math:`Q = 2^d` corners, value weights and gradient weights

.. math::
    y_{pq} = x_p + R_p s_q, \qquad w_{pq} = 2^{-d}, \qquad
    g_{pq} = 2^{-d} R_p^{-T} s_q, \qquad R_p = F_p \operatorname{diag}(\ell_p),

with :math:`s_q \in \{-1, 1\}^d` (:func:`fempm.particles.corners.corner_signs`). The corners
are made and located in one pass (:func:`locate_corners`: the last step's cell of the corner,
the particle's cell, then its vertex star), and the passes compute :math:`g_{pq}` from
:math:`F_p` and :math:`\ell_p` (:func:`corner_frame`) instead of reading it from memory: CPDI1
keeps only each corner's cell and reference coordinates from step to step.
:func:`cpdi1_samples` makes the three arrays (the reference, and the corners the vertex star
does not hold).
"""

from __future__ import annotations

import functools

import numpy as np

from fempm.kernels.bundles import Star
from fempm.kernels.choice import INLINE
from fempm.kernels.shape import AVAILABLE, CELLS, is_affine

__all__ = ["corner_frame", "corner_gradient", "cpdi1_samples", "locate_corners"]

if AVAILABLE:
    from numba import njit

    from fempm.kernels.corners import inverse
    from fempm.kernels.shape import inside_after_pull_back, star_search

    @njit(inline=INLINE)
    def pull(y0, y1, x0, K, e, tol, simplex):  # pragma: no cover - compiled
        """(inside, X0, X1): :func:`fempm.kernels.shape.inside_after_pull_back` in the affine
        triangle (``simplex``) or parallelogram ``e``."""
        d0, d1 = y0 - x0[e, 0], y1 - x0[e, 1]
        X0 = K[e, 0, 0] * d0 + K[e, 0, 1] * d1
        X1 = K[e, 1, 0] * d0 + K[e, 1, 1] * d1
        if simplex:
            return X0 >= -tol and X1 >= -tol and X0 + X1 <= 1.0 + tol, X0, X1
        return X0 >= -tol and X1 >= -tol and X0 <= 1.0 + tol and X1 <= 1.0 + tol, X0, X1

    @njit(inline=INLINE)
    def corner_frame(F, lp, p, d, R, Ri):  # pragma: no cover - compiled
        r"""``R`` <- :math:`F_p \operatorname{diag}(\ell_p)`, ``Ri`` <- :math:`R^{-1}` (the
        gradient weight of corner :math:`s` is :math:`Q^{-1} \sum_j R^{-1}_{ji} s_j`)."""
        for i in range(d):
            for j in range(d):
                R[i, j] = F[p, i, j] * lp[p, j]
        inverse(R, d, Ri)

    @njit(inline=INLINE)
    def corner_gradient(Ri, signs, q, i, d):  # pragma: no cover - compiled
        r""":math:`(R^{-T} s_q)_i = \sum_j R^{-1}_{ji} s_{qj}` (times :math:`Q^{-1}`, corner
        ``q``'s gradient weight)."""
        t = 0.0
        for j in range(d):
            t += Ri[j, i] * signs[q, j]
        return t

    @njit(cache=True, error_model="numpy")
    def _cpdi1_samples(x, F, lp, signs, y, w, g):  # pragma: no cover - compiled
        n, d = x.shape
        Q = signs.shape[0]
        R = np.empty((d, d))
        Ri = np.empty((d, d))
        share = 1.0 / Q
        for p in range(n):
            corner_frame(F, lp, p, d, R, Ri)
            for q in range(Q):
                w[p, q] = share
                for i in range(d):
                    s = x[p, i]
                    for j in range(d):
                        s += R[i, j] * signs[q, j]
                    y[p * Q + q, i] = s
                    g[p, q, i] = share * corner_gradient(Ri, signs, q, i, d)


def cpdi1_samples(x, F, lp, signs, out=None):
    """CPDI1 samples of particles at ``x`` (n, d) with ``F`` (n, d, d), half-widths ``lp``
    (n, d) and corner ``signs`` (Q, d): (y (n Q, d), w (n, Q), g (n, Q, d)), into ``out`` if
    given (arrays of those shapes)."""
    n, d = x.shape
    Q = len(signs)
    y, w, g = out if out is not None else (np.empty((n * Q, d)), np.empty((n, Q)), np.empty((n, Q, d)))
    _cpdi1_samples(np.ascontiguousarray(x), np.ascontiguousarray(F), np.ascontiguousarray(lp), signs, y, w, g)
    return y, w, g


@functools.cache
def _locate_kernel(cell: str):
    T, _, SIMPLEX = CELLS[cell]
    AFFINE = is_affine(cell)

    @njit(cache=True, error_model="numpy")
    def locate(x, F, lp, signs, cells, x0, K, star, tol, guess, sc, Y):  # pragma: no cover - compiled
        Q = signs.shape[0]
        R, Ri = np.empty((T, T)), np.empty((T, T))
        y, X = np.empty((1, T)), np.empty((1, T))
        missing = 0
        guessed = guess.shape[0] == len(cells)
        for p in range(len(cells)):
            corner_frame(F, lp, p, T, R, Ri)
            c = cells[p]
            for q in range(Q):
                r = p * Q + q
                for i in range(T):
                    s = x[p, i]
                    for j in range(T):
                        s += R[i, j] * signs[q, j]
                    y[0, i] = s
                    X[0, i] = Y[r, i]  # Newton's first guess on multilinear cells
                e = guess[p, q] if guessed else -1  # as fempm.kernels.sample_location.locate_samples
                if not (e >= 0 and e != c and inside_after_pull_back(y, 0, x0, K, e, SIMPLEX, T, tol, X, AFFINE)):
                    if inside_after_pull_back(y, 0, x0, K, c, SIMPLEX, T, tol, X, AFFINE):
                        e = c
                    else:
                        e = star_search(y, 0, x0, K, c, star, SIMPLEX, T, tol, X, AFFINE)
                sc[p, q] = e
                for i in range(T):
                    Y[r, i] = X[0, i]
                if e < 0:
                    missing += 1
        return missing

    return locate


@functools.cache
def _planar_locate_kernel(simplex: bool):
    """:func:`_locate_kernel` on affine triangles (``simplex``) or quadrilaterals in local
    scalars (the same arithmetic): a corner and its pull-back never go through scratch arrays
    the compiler must take as aliasing the outputs."""

    @njit(cache=True, error_model="numpy")
    def locate(x, F, lp, signs, cells, x0, K, star, tol, guess, sc, Y):  # pragma: no cover - compiled
        Q = signs.shape[0]
        y, X = np.empty((1, 2)), np.empty((1, 2))  # for the vertex-star search
        missing = 0
        guessed = guess.shape[0] == len(cells)
        for p in range(len(cells)):
            r00, r01 = F[p, 0, 0] * lp[p, 0], F[p, 0, 1] * lp[p, 1]
            r10, r11 = F[p, 1, 0] * lp[p, 0], F[p, 1, 1] * lp[p, 1]
            c = cells[p]
            for q in range(Q):
                s0, s1 = signs[q, 0], signs[q, 1]
                y0 = x[p, 0] + r00 * s0 + r01 * s1
                y1 = x[p, 1] + r10 * s0 + r11 * s1
                e = guess[p, q] if guessed else -1
                found, X0, X1 = False, 0.0, 0.0
                if e >= 0 and e != c:
                    found, X0, X1 = pull(y0, y1, x0, K, e, tol, simplex)
                if not found:
                    e = c
                    found, X0, X1 = pull(y0, y1, x0, K, c, tol, simplex)
                if not found:
                    y[0, 0], y[0, 1] = y0, y1
                    e = star_search(y, 0, x0, K, c, star, simplex, 2, tol, X, True)
                    X0, X1 = X[0, 0], X[0, 1]
                    if e < 0:
                        missing += 1
                sc[p, q] = e
                Y[p * Q + q, 0], Y[p * Q + q, 1] = X0, X1
        return missing

    return locate


def locate_corners(x, F, lp, signs, cells, x0, K, star: Star, cell: str, tol: float, guess=None, out=None):
    """Cells (n, Q) and reference coordinates (n Q, t) of the CPDI1 corners of particles at
    ``x`` in ``cells`` (:func:`fempm.kernels.sample_location.locate_samples` with the corners made in the
    pass), and the number of corners on no cell of the search (cell -1)."""
    n = len(cells)
    Q, t = len(signs), CELLS[cell][0]
    sc, Y = out if out is not None else (np.full((n, Q), -1, dtype=np.int32), np.zeros((n * Q, t)))
    guess = np.zeros((0, Q), dtype=np.int32) if guess is None else guess
    kernel = _planar_locate_kernel(cell == "triangle") if cell in ("triangle", "quadrilateral") else _locate_kernel(cell)
    missing = kernel(x, F, lp, signs, cells, x0, K, star, float(tol), guess, sc, Y)
    return sc, Y, int(missing)
