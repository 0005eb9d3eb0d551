r"""The implicit step's per-particle passes (:mod:`fempm.implicit`), compiled.

* :func:`increment_gradients`: :math:`G_p = \sum_a \Delta u_a \otimes \nabla N_a(x_p)` (n, d, d).
* :func:`increment_determinants`: :math:`\det(I + G_p)` (n,), closed form.
* :func:`nominal`: the nominal stress :math:`P = J_\Delta \sigma \Delta F^{-T}` and, from the law's
  :math:`\mathbb{D} = \partial \sigma / \partial G`, its tangent
  :math:`\mathbb{A}_{imkl} = J_\Delta (\tilde P_{im} \Delta F^{-1}_{lk} + \mathbb{D}_{ijkl}
  \Delta F^{-1}_{mj} - \tilde P_{il} \Delta F^{-1}_{mk})` (:mod:`fempm.implicit.nominal`).
* :func:`linear_elastic_tangent`: :math:`\lambda \delta_{ij} F_{lk} + \mu (\delta_{ik} F_{lj}
  + \delta_{jk} F_{li})` (:class:`fempm.materials.LinearElastic`).

The compiled forms take numpy's error model (a zero determinant leaves the inverse infinite and
the nominal stress NaN, which its caller refuses; python's model would test every division) and
loops whose sizes are compile-time constants, one kernel per (d, dofs a particle); their loops
carry no branch (a conditional store serialises the loop: the determinants of a 2D increment
took 17x as long with one). Each ``*_numpy`` is the
reference its compiled form is tested against
(``tests/kernels/test_implicit_kernels.py``); :func:`fempm.kernels.choice.pick` chooses. The
particles' tangent blocks are :mod:`fempm.kernels.implicit_blocks`.
"""

from __future__ import annotations

import functools

import numpy as np
import numpy.typing as npt

from fempm.kernels.choice import INLINE, pick

__all__ = ["increment_determinants", "increment_gradients", "linear_elastic_tangent", "nominal"]


# -- the numpy references -------------------------------------------------------------------------
def increment_gradients_numpy(du: npt.NDArray, dofs: npt.NDArray, gradients: npt.NDArray) -> npt.NDArray:
    return np.einsum("pak,pal->pkl", du[dofs], gradients)


def increment_determinants_numpy(G: npt.NDArray) -> npt.NDArray:
    return np.linalg.det(np.eye(G.shape[1]) + G)


def nominal_numpy(sigma: npt.NDArray, D: npt.NDArray | None, G: npt.NDArray):
    """(P, A or None, J); J the increments' determinants (no check)."""
    d = G.shape[1]
    dF = np.eye(d) + G
    J = np.linalg.det(dF)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.linalg.inv(dF) if np.all(J != 0.0) else np.full_like(dF, np.nan)
    Pt = sigma @ np.swapaxes(inv, 1, 2)
    if D is None:
        return J[:, None, None] * Pt, None, J
    A = np.einsum("nijkl,nmj->nimkl", D, inv, optimize=True)
    A += Pt[:, :, :, None, None] * np.swapaxes(inv, 1, 2)[:, None, None, :, :]  # P~_im inv_lk
    A -= Pt[:, :, None, None, :] * inv[:, None, :, :, None]  # P~_il inv_mk
    return J[:, None, None] * Pt, J[:, None, None, None, None] * A, J


def linear_elastic_tangent_numpy(F: npt.NDArray, lam: float, mu: float) -> npt.NDArray:
    eye = np.eye(F.shape[1])
    return (lam * np.einsum("ij,nlk->nijkl", eye, F) + mu * np.einsum("ik,nlj->nijkl", eye, F)
            + mu * np.einsum("jk,nli->nijkl", eye, F))


try:
    from numba import njit

    @njit(inline=INLINE)
    def _det(G, p, d):  # pragma: no cover - compiled
        """det(I + G[p]) (d x d)."""
        if d == 1:
            return 1.0 + G[p, 0, 0]
        if d == 2:
            return (1.0 + G[p, 0, 0]) * (1.0 + G[p, 1, 1]) - G[p, 0, 1] * G[p, 1, 0]
        m00, m01, m02 = 1.0 + G[p, 0, 0], G[p, 0, 1], G[p, 0, 2]
        m10, m11, m12 = G[p, 1, 0], 1.0 + G[p, 1, 1], G[p, 1, 2]
        m20, m21, m22 = G[p, 2, 0], G[p, 2, 1], 1.0 + G[p, 2, 2]
        return m00 * (m11 * m22 - m12 * m21) + m01 * (m12 * m20 - m10 * m22) + m02 * (m10 * m21 - m11 * m20)

    @njit(inline=INLINE)
    def _det_inv(G, p, d, inv):  # pragma: no cover - compiled
        """det(I + G[p]) and its inverse into ``inv`` (d x d; infinite or NaN where det = 0: no
        branch, which would leave the stores conditional and the loop several times slower)."""
        if d == 1:
            a = 1.0 + G[p, 0, 0]
            inv[0, 0] = 1.0 / a
            return a
        if d == 2:
            a, b, c, e = 1.0 + G[p, 0, 0], G[p, 0, 1], G[p, 1, 0], 1.0 + G[p, 1, 1]
            J = a * e - b * c
            r = 1.0 / J
            inv[0, 0], inv[0, 1], inv[1, 0], inv[1, 1] = e * r, -b * r, -c * r, a * r
            return J
        m00, m01, m02 = 1.0 + G[p, 0, 0], G[p, 0, 1], G[p, 0, 2]
        m10, m11, m12 = G[p, 1, 0], 1.0 + G[p, 1, 1], G[p, 1, 2]
        m20, m21, m22 = G[p, 2, 0], G[p, 2, 1], 1.0 + G[p, 2, 2]
        c00, c01, c02 = m11 * m22 - m12 * m21, m12 * m20 - m10 * m22, m10 * m21 - m11 * m20
        J = m00 * c00 + m01 * c01 + m02 * c02
        r = 1.0 / J
        inv[0, 0], inv[1, 0], inv[2, 0] = c00 * r, c01 * r, c02 * r
        inv[0, 1] = (m02 * m21 - m01 * m22) * r
        inv[1, 1] = (m00 * m22 - m02 * m20) * r
        inv[2, 1] = (m01 * m20 - m00 * m21) * r
        inv[0, 2] = (m01 * m12 - m02 * m11) * r
        inv[1, 2] = (m02 * m10 - m00 * m12) * r
        inv[2, 2] = (m00 * m11 - m01 * m10) * r
        return J

    @functools.cache
    def _increment_gradients_kernel(k: int, d: int):
        """:func:`increment_gradients` for ``k`` dofs a particle in dimension ``d`` (the loops'
        sizes compile-time constants: 2-3x as fast as read at run time)."""

        @njit(cache=True, error_model="numpy")
        def gradients(du, dofs, grads):  # pragma: no cover - compiled
            n = dofs.shape[0]
            G = np.empty((n, d, d))
            for p in range(n):
                for i in range(d):
                    for m in range(d):
                        s = 0.0
                        for a in range(k):
                            s += du[dofs[p, a], i] * grads[p, a, m]
                        G[p, i, m] = s
            return G

        return gradients

    def increment_gradients_numba(du, dofs, gradients):
        return _increment_gradients_kernel(*gradients.shape[1:])(np.ascontiguousarray(du), np.ascontiguousarray(dofs),
                                                                 np.ascontiguousarray(gradients))

    @functools.cache
    def _determinants_kernel(d: int):
        """:func:`increment_determinants` in dimension ``d`` (closed form, vectorised)."""

        @njit(cache=True, error_model="numpy")
        def determinants(G):  # pragma: no cover - compiled
            n = G.shape[0]
            J = np.empty(n)
            for p in range(n):
                J[p] = _det(G, p, d)
            return J

        return determinants

    def increment_determinants_numba(G):
        return _determinants_kernel(G.shape[1])(np.ascontiguousarray(G))

    @functools.cache
    def _nominal_kernel(d: int, tangent: bool):
        r""":math:`P_p` (and with ``tangent`` :math:`\mathbb{A}_p`) of dimension ``d``, the loops'
        sizes compile-time constants (unrolled: 2-3x as fast as with the sizes read at run time)."""

        @njit(cache=True, error_model="numpy")
        def nominal(sigma, D, G):  # pragma: no cover - compiled
            n = G.shape[0]
            P = np.empty((n, d, d))
            A = np.empty((n if tangent else 0, d, d, d, d))
            J = np.empty(n)
            inv = np.empty((d, d))
            Pt = np.empty((d, d))
            for p in range(n):
                Jp = _det_inv(G, p, d, inv)  # (det = 0: an infinite inverse, P and A NaN)
                J[p] = Jp
                for i in range(d):
                    for m in range(d):
                        s = 0.0
                        for j in range(d):
                            s += sigma[p, i, j] * inv[m, j]
                        Pt[i, m] = s
                        P[p, i, m] = Jp * s
                if tangent:
                    for i in range(d):
                        for m in range(d):
                            for k in range(d):
                                for l in range(d):
                                    s = Pt[i, m] * inv[l, k] - Pt[i, l] * inv[m, k]
                                    for j in range(d):
                                        s += D[p, i, j, k, l] * inv[m, j]
                                    A[p, i, m, k, l] = Jp * s
            return P, A, J

        return nominal

    def nominal_numba(sigma, D, G):
        d = G.shape[1]
        P, A, J = _nominal_kernel(d, D is not None)(np.ascontiguousarray(sigma), np.zeros((0,) + (d,) * 4) if D is None
                                                    else np.ascontiguousarray(D), np.ascontiguousarray(G))
        return P, (A if D is not None else None), J

    @functools.cache
    def _linear_elastic_tangent_kernel(d: int):
        """:func:`linear_elastic_tangent` in dimension ``d`` (the loops' sizes compile-time constants)."""

        @njit(cache=True, error_model="numpy")
        def tangent(F, lam, mu):  # pragma: no cover - compiled
            n = F.shape[0]
            D = np.zeros((n, d, d, d, d))
            for p in range(n):
                for i in range(d):
                    for k in range(d):
                        for l in range(d):
                            D[p, i, i, k, l] += lam * F[p, l, k]
                            for j in range(d):
                                if i == k:
                                    D[p, i, j, k, l] += mu * F[p, l, j]
                                if j == k:
                                    D[p, i, j, k, l] += mu * F[p, l, i]
            return D

        return tangent

    def linear_elastic_tangent_numba(F, lam, mu):
        return _linear_elastic_tangent_kernel(F.shape[1])(np.ascontiguousarray(F), float(lam), float(mu))

except ImportError:  # pragma: no cover - numba is a dependency
    increment_gradients_numba = increment_gradients_numpy
    increment_determinants_numba = increment_determinants_numpy
    nominal_numba = nominal_numpy
    linear_elastic_tangent_numba = linear_elastic_tangent_numpy

increment_gradients = pick(increment_gradients_numba, increment_gradients_numpy)
increment_determinants = pick(increment_determinants_numba, increment_determinants_numpy)
nominal = pick(nominal_numba, nominal_numpy)
linear_elastic_tangent = pick(linear_elastic_tangent_numba, linear_elastic_tangent_numpy)
