r"""F-bar's first two passes (:mod:`fempm.kernels.fbar`) on tetrahedra and affine hexahedra, with
the per-particle quantities in local scalars (as :mod:`fempm.kernels.solid`: the generic loops
keep :math:`L_p`, the basis and :math:`\bar F_p` in small scratch arrays, which the compiler must
treat as possibly aliasing the arrays the passes write). The generic kernels of
:mod:`fempm.kernels.fbar` are their reference (``tests/kernels/test_fbar_kernels.py``).

The passes are whole kernels, not helpers inlined into the generic ones: inlined there, with
their arrays handed over in a tuple, the measure pass on tetrahedra took four times as long.
"""

from __future__ import annotations

import functools

import numpy as np

from fempm.kernels.choice import INLINE
from fempm.kernels.shape import AVAILABLE

__all__ = ["deform_kernel", "measure_kernel", "root"]

if AVAILABLE:
    from numba import njit

    from fempm.kernels.kinematics import law_at
    from fempm.kernels.particle_checks import count_j
    from fempm.kernels.patch import add_node, nodal_ratio
    from fempm.kernels.solid import gather as solid_gather
    from fempm.kernels.solid import inverse_jacobian as solid_inverse_jacobian
    from fempm.kernels.solid import value as solid_value

    @njit(inline=INLINE)
    def root(x, D):  # pragma: no cover - compiled
        r""":math:`x^{1/D}` (NaN for x < 0 and D > 1, as numpy's power). In 3D, where
        :math:`|x - 1| < 1/4` (the ratio of a patch's average to a particle's own :math:`\Delta J`
        in all but violent steps), two Halley iterations
        :math:`y \leftarrow y (y^3 + 2x) / (2 y^3 + x)` from :math:`1 + (x - 1)/3` (cubic
        convergence from an error below :math:`(x-1)^2/9`: round-off after the second),
        several times as fast as the library's cube root; elsewhere that root."""
        if D == 1:
            return x
        if D == 2:
            return np.sqrt(x)
        if abs(x - 1.0) < 0.25:
            y = 1.0 + (x - 1.0) * (1.0 / 3.0)
            y3 = y * y * y
            y = y * (y3 + 2.0 * x) / (2.0 * y3 + x)
            y3 = y * y * y
            return y * (y3 + 2.0 * x) / (2.0 * y3 + x)
        return np.cbrt(x) if x >= 0.0 else np.nan


@functools.cache
def measure_kernel(hexa: bool):
    """:func:`fempm.kernels.fbar.measure_kernel` on tetrahedra or (``hexa``) affine hexahedra."""
    NK, QUAD = (8 if hexa else 4), hexa

    @njit(cache=True, error_model="numpy")
    def measure(where, v_new, F, volume, body, by_trace, dt, L, value, out, dirty):  # pragma: no cover
        """The pass on tetrahedra and affine hexahedra, in scalars (:mod:`fempm.kernels.solid`)."""
        cells, X, K, cell_dofs = where
        bodies = out.shape[1] // 2
        for p in range(len(cells)):
            c = cells[p]
            X0, X1, X2 = X[p, 0], X[p, 1], X[p, 2]
            k = solid_inverse_jacobian(K, c)
            L00, L01, L02, L10, L11, L12, L20, L21, L22 = solid_gather(
                c, 0, (X0, X1, X2), k, cell_dofs, v_new, v_new, False, True, NK, QUAD, (False, k))[6]
            b = body[p]
            if by_trace[b]:
                f = dt * (L00 * F[p, 0, 0] + L01 * F[p, 1, 0] + L02 * F[p, 2, 0] + L10 * F[p, 0, 1]
                          + L11 * F[p, 1, 1] + L12 * F[p, 2, 1] + L20 * F[p, 0, 2] + L21 * F[p, 1, 2]
                          + L22 * F[p, 2, 2])
            else:
                a, bb, cc = 1.0 + dt * L00, dt * L01, dt * L02
                d, e, g = dt * L10, 1.0 + dt * L11, dt * L12
                h, q, r = dt * L20, dt * L21, 1.0 + dt * L22
                f = a * (e * r - g * q) - bb * (d * r - g * h) + cc * (d * q - e * h)
            L[p, 0, 0], L[p, 0, 1], L[p, 0, 2] = L00, L01, L02
            L[p, 1, 0], L[p, 1, 1], L[p, 1, 2] = L10, L11, L12
            L[p, 2, 0], L[p, 2, 1], L[p, 2, 2] = L20, L21, L22
            value[p] = f
            w = volume[p]
            for a in range(NK):
                add_node(out, dirty, cell_dofs[c, a], b, bodies, solid_value(a, X0, X1, X2, QUAD) * w, f)

    return measure


@functools.cache
def deform_kernel(hexa: bool):
    r""":func:`fempm.kernels.fbar.deform_kernel` without :math:`\bar L_p` on tetrahedra or
    (``hexa``) affine hexahedra."""
    NK, HEXA = (8 if hexa else 4), hexa

    @njit(cache=True, error_model="numpy")
    def deform(where, nodal, by_trace, dt, L, value, state, laws):  # pragma: no cover - compiled
        r"""The pass on tetrahedra and affine hexahedra without :math:`\bar L_p`, in scalars."""
        cells, X, _, cell_dofs = where
        F, volume0, volume, sigma, body = state.F, state.volume0, state.volume, state.sigma, state.body
        law, lam, mu = laws.law, laws.lam, laws.mu
        bodies = nodal.shape[1] // 2
        nonfinite_j, inverted, jmin, jmax = 0, 0, np.inf, -np.inf
        for p in range(len(cells)):
            c = cells[p]
            X0, X1, X2 = X[p, 0], X[p, 1], X[p, 2]
            b = body[p]
            averaged = 0.0
            for a in range(NK):
                averaged += solid_value(a, X0, X1, X2, HEXA) * nodal_ratio(nodal, cell_dofs[c, a], b, bodies)
            scale, shift = 1.0, 0.0
            if by_trace[b]:
                shift = (averaged - value[p]) * (1.0 / 3.0)
            else:
                scale = root(averaged / value[p], 3)
            s0, s1 = scale * dt, scale
            d00, d01, d02 = s1 + s0 * L[p, 0, 0], s0 * L[p, 0, 1], s0 * L[p, 0, 2]  # scale (I + dt L)
            d10, d11, d12 = s0 * L[p, 1, 0], s1 + s0 * L[p, 1, 1], s0 * L[p, 1, 2]
            d20, d21, d22 = s0 * L[p, 2, 0], s0 * L[p, 2, 1], s1 + s0 * L[p, 2, 2]
            f00, f01, f02, f10, f11, f12 = F[p, 0, 0], F[p, 0, 1], F[p, 0, 2], F[p, 1, 0], F[p, 1, 1], F[p, 1, 2]
            f20, f21, f22 = F[p, 2, 0], F[p, 2, 1], F[p, 2, 2]
            n00 = d00 * f00 + d01 * f10 + d02 * f20 + shift
            n01 = d00 * f01 + d01 * f11 + d02 * f21
            n02 = d00 * f02 + d01 * f12 + d02 * f22
            n10 = d10 * f00 + d11 * f10 + d12 * f20
            n11 = d10 * f01 + d11 * f11 + d12 * f21 + shift
            n12 = d10 * f02 + d11 * f12 + d12 * f22
            n20 = d20 * f00 + d21 * f10 + d22 * f20
            n21 = d20 * f01 + d21 * f11 + d22 * f21
            n22 = d20 * f02 + d21 * f12 + d22 * f22 + shift
            F[p, 0, 0], F[p, 0, 1], F[p, 0, 2] = n00, n01, n02
            F[p, 1, 0], F[p, 1, 1], F[p, 1, 2] = n10, n11, n12
            F[p, 2, 0], F[p, 2, 1], F[p, 2, 2] = n20, n21, n22
            J = n00 * (n11 * n22 - n12 * n21) - n01 * (n10 * n22 - n12 * n20) + n02 * (n10 * n21 - n11 * n20)
            volume[p] = J * volume0[p]
            ok, nonfinite_j, inverted, jmin, jmax = count_j(J, nonfinite_j, inverted, jmin, jmax)
            if ok:
                law_at(law[b], F, p, 3, J, lam[b], mu[b], sigma)
        return nonfinite_j, inverted, jmin, jmax

    return deform
