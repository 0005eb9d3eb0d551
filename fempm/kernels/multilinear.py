r"""Newton's pull-back on multilinear cells (quadrilaterals and hexahedra with straight edges
that are not parallelograms or parallelepipeds), for the compiled passes: the pull-back and
the basis are functions compiled once that the passes call (inlined, their code made every
kernel, affine or not, compile about 4 times as long).

The map of such a cell is :math:`x(X) = \sum_a \hat N_a(X) x_a` over its vertices (basix order),
its Jacobian :math:`J(X) = \sum_a x_a \otimes \nabla_X \hat N_a(X)` varies over the cell
(:func:`multilinear_map`, inverted by :func:`inverse3`), and the pull-back iterates

.. math::
    X \leftarrow X - J(X)^{-1} \big(x(X) - x\big)

(:func:`multilinear_pull_back`; the numpy reference is
:meth:`fempm.meshes.geometry.CellGeometry.pull_back`). :func:`quad_pull_back` is its closed
form on quadrilaterals for a moving particle, which knows the size of its first step.
"""

from __future__ import annotations

import numpy as np

from fempm.kernels.choice import INLINE

__all__ = ["NEWTON_FLOOR", "NEWTON_MAX", "NEWTON_TOL", "quad_pull_back"]

#: a step of Newton's pull-back on multilinear cells below which it has converged (reference
#: coordinates; the numpy pull-back's tolerance)
NEWTON_TOL = 1e-12
#: a step below which Newton's pull-back has reached round-off when it no longer halves
NEWTON_FLOOR = 1e-7
#: Newton steps after which a pull-back that has not converged lies outside the cell
NEWTON_MAX = 25

try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency
    njit = None

if njit is not None:
    @njit(inline=INLINE)
    def vertex_basis(a, X0, X1, X2, t):  # pragma: no cover - compiled
        r"""The reference basis function of vertex ``a`` (basix order: bit ``i`` of ``a`` is the
        vertex's coordinate ``i``) at :math:`(X_0, X_1, X_2)` and its reference gradient, as
        4 scalars :math:`\hat N_a, \partial_0 \hat N_a, \partial_1 \hat N_a, \partial_2 \hat N_a`
        (``t`` = 2: the factor of :math:`X_2` is 1, its derivative 0)."""
        b0, b1 = a & 1, (a >> 1) & 1
        f0 = X0 if b0 else 1.0 - X0
        f1 = X1 if b1 else 1.0 - X1
        d0 = 1.0 if b0 else -1.0
        d1 = 1.0 if b1 else -1.0
        if t == 3:
            b2 = (a >> 2) & 1
            f2 = X2 if b2 else 1.0 - X2
            d2 = 1.0 if b2 else -1.0
        else:
            f2, d2 = 1.0, 0.0
        return f0 * f1 * f2, d0 * f1 * f2, f0 * d1 * f2, f0 * f1 * d2

    @njit(inline=INLINE)
    def multilinear_map(X0, X1, X2, xc, c, t):  # pragma: no cover - compiled
        r"""The multilinear map of cell ``c`` (vertices ``xc[c]``, basix order) at the
        reference point :math:`(X_0, X_1, X_2)` (``t`` = 2: :math:`X_2` unused): the point
        :math:`y = \sum_a \hat N_a(X) x_a` and :math:`J = \sum_a x_a \otimes \nabla_X \hat N_a`,
        as 3 + 9 scalars (``t`` = 2: :math:`y_2 = 0` and the third row and column of the
        identity, so that :func:`inverse3` serves both dimensions)."""
        y0 = y1 = y2 = 0.0
        j00 = j01 = j02 = j10 = j11 = j12 = j20 = j21 = j22 = 0.0
        for a in range(4 if t == 2 else 8):
            n, g0, g1, g2 = vertex_basis(a, X0, X1, X2, t)
            u0, u1 = xc[c, a, 0], xc[c, a, 1]
            y0 += n * u0
            y1 += n * u1
            j00 += u0 * g0
            j01 += u0 * g1
            j10 += u1 * g0
            j11 += u1 * g1
            if t == 3:
                u2 = xc[c, a, 2]
                y2 += n * u2
                j02 += u0 * g2
                j12 += u1 * g2
                j20 += u2 * g0
                j21 += u2 * g1
                j22 += u2 * g2
        if t == 2:
            j22 = 1.0
        return y0, y1, y2, j00, j01, j02, j10, j11, j12, j20, j21, j22

    @njit(inline=INLINE)
    def inverse3(j00, j01, j02, j10, j11, j12, j20, j21, j22):  # pragma: no cover - compiled
        """The inverse of a 3x3 matrix by cofactors, row by row (9 scalars)."""
        c00 = j11 * j22 - j12 * j21
        c01 = j12 * j20 - j10 * j22
        c02 = j10 * j21 - j11 * j20
        r = 1.0 / (j00 * c00 + j01 * c01 + j02 * c02)
        return (c00 * r, (j02 * j21 - j01 * j22) * r, (j01 * j12 - j02 * j11) * r,
                c01 * r, (j00 * j22 - j02 * j20) * r, (j02 * j10 - j00 * j12) * r,
                c02 * r, (j01 * j20 - j00 * j21) * r, (j00 * j11 - j01 * j10) * r)

    @njit(cache=True)  # not inlined: compiled once, not into every kernel
    def multilinear_pull_back(x, p, xc, c, t, tol, X):  # pragma: no cover - compiled
        """X[p] <- the reference coordinates of ``x[p]`` in the multilinear cell ``c`` by Newton's
        method, from ``X[p]`` where it is finite and near the cell (else the centre), until a
        step is below :data:`NEWTON_TOL` (or, below :data:`NEWTON_FLOOR`, no longer halves the
        one before: the round-off of cells far from the origin); whether the point lies in the reference cell within
        ``tol`` (a point where Newton does not converge lies outside, X[p] NaN)."""
        X0, X1 = X[p, 0], X[p, 1]
        X2 = X[p, 2] if t == 3 else 0.0
        if not (abs(X0 - 0.5) < 1.5 and abs(X1 - 0.5) < 1.5 and abs(X2 - 0.5) < 1.5):  # also NaN
            X0 = X1 = 0.5
            X2 = 0.5 if t == 3 else 0.0
        z0, z1 = x[p, 0], x[p, 1]
        z2 = x[p, 2] if t == 3 else 0.0
        done = False
        last = np.inf
        for _ in range(NEWTON_MAX):
            y0, y1, y2, j00, j01, j02, j10, j11, j12, j20, j21, j22 = multilinear_map(X0, X1, X2, xc, c, t)
            k00, k01, k02, k10, k11, k12, k20, k21, k22 = inverse3(j00, j01, j02, j10, j11, j12, j20, j21, j22)
            r0, r1, r2 = y0 - z0, y1 - z1, y2 - z2
            e0 = k00 * r0 + k01 * r1 + k02 * r2
            e1 = k10 * r0 + k11 * r1 + k12 * r2
            e2 = k20 * r0 + k21 * r1 + k22 * r2 if t == 3 else 0.0
            X0 -= e0
            X1 -= e1
            X2 -= e2
            step = max(abs(e0), abs(e1), abs(e2))
            if not (step < 1e3):  # diverged, or NaN
                break
            if step < NEWTON_TOL or (step < NEWTON_FLOOR and step > 0.5 * last):  # converged, or at round-off
                done = True
                break
            last = step
        if not done:
            X0 = X1 = X2 = np.nan
        X[p, 0], X[p, 1] = X0, X1
        if t == 3:
            X[p, 2] = X2
        return done and X0 >= -tol and X1 >= -tol and X2 >= -tol and X0 <= 1.0 + tol and X1 <= 1.0 + tol and \
            X2 <= 1.0 + tol

    @njit(cache=True)  # not inlined: compiled once, not into every kernel
    def multilinear_shape(X, p, xc, c, t, k, N, G):  # pragma: no cover - compiled
        """Values ``N`` (k,) and physical gradients ``G`` (k, t) of the multilinear basis at
        ``X[p]`` in the cell of vertices ``xc[c]``, the inverse Jacobian computed there."""
        X0, X1 = X[p, 0], X[p, 1]
        X2 = X[p, 2] if t == 3 else 0.0
        _, _, _, j00, j01, j02, j10, j11, j12, j20, j21, j22 = multilinear_map(X0, X1, X2, xc, c, t)
        k00, k01, k02, k10, k11, k12, k20, k21, k22 = inverse3(j00, j01, j02, j10, j11, j12, j20, j21, j22)
        for a in range(k):
            n, g0, g1, g2 = vertex_basis(a, X0, X1, X2, t)
            N[a] = n
            G[a, 0] = g0 * k00 + g1 * k10 + g2 * k20
            G[a, 1] = g0 * k01 + g1 * k11 + g2 * k21
            if t == 3:
                G[a, 2] = g0 * k02 + g1 * k12 + g2 * k22

    @njit(cache=True)  # not inlined: compiled once, not into every kernel
    def quad_pull_back(x, p, xc, c, tol, X, seed):  # pragma: no cover - compiled
        r""":func:`multilinear_pull_back` on a quadrilateral in closed form (:math:`2 \times 2`),
        from ``X[p]``, itself a Newton step of size ``seed`` from a converged point (a particle
        moved by :math:`u`: :math:`X + K(X) u`; ``inf`` if not). Newton converges
        quadratically, :math:`s_{k+1} \approx C s_k^2`; it also stops once the next step, so
        estimated from the last two (:math:`s_k^3 / s_{k-1}^2`), is below :data:`NEWTON_TOL`
        and the step below :data:`NEWTON_FLOOR`: from a seeded start one iteration instead of
        two. Whether the point lies in the reference cell within ``tol``."""
        X0, X1 = X[p, 0], X[p, 1]
        last = seed
        if not (abs(X0 - 0.5) < 1.5 and abs(X1 - 0.5) < 1.5):  # also NaN
            X0 = X1 = 0.5
            last = np.inf
        z0, z1 = x[p, 0], x[p, 1]
        a0, a1 = xc[c, 0, 0], xc[c, 0, 1]
        b0, b1 = xc[c, 1, 0] - a0, xc[c, 1, 1] - a1  # x = a + b X0 + e X1 + f X0 X1
        e0, e1 = xc[c, 2, 0] - a0, xc[c, 2, 1] - a1
        f0, f1 = xc[c, 3, 0] - xc[c, 2, 0] - b0, xc[c, 3, 1] - xc[c, 2, 1] - b1
        done = False
        for _ in range(NEWTON_MAX):
            r0 = a0 + b0 * X0 + e0 * X1 + f0 * X0 * X1 - z0
            r1 = a1 + b1 * X0 + e1 * X1 + f1 * X0 * X1 - z1
            j00, j01 = b0 + f0 * X1, e0 + f0 * X0
            j10, j11 = b1 + f1 * X1, e1 + f1 * X0
            det = j00 * j11 - j01 * j10
            d0 = (j11 * r0 - j01 * r1) / det
            d1 = (j00 * r1 - j10 * r0) / det
            X0 -= d0
            X1 -= d1
            step = max(abs(d0), abs(d1))
            if not (step < 1e3):  # diverged, or NaN
                break
            if step < NEWTON_TOL or (step < NEWTON_FLOOR
                                     and (step > 0.5 * last or step * step * step < NEWTON_TOL * last * last)):
                done = True  # converged, at round-off, or the next step below the tolerance
                break
            last = step
        if not done:
            X0 = X1 = np.nan
        X[p, 0], X[p, 1] = X0, X1
        return done and X0 >= -tol and X1 >= -tol and X0 <= 1.0 + tol and X1 <= 1.0 + tol
