r"""The affine transfers' per-particle pieces of the scalar 3D passes (:mod:`fempm.kernels.solid`),
written out for tetrahedra and affine hexahedra: the generic ones are
:mod:`fempm.kernels.affine`, the reference :mod:`fempm.transfer.affine`.

On an affine cell with the Jacobian :math:`J = K_c^{-1}` the offsets of the particle's dofs are
:math:`r_a = x_a - x_p = J (X_a - X_p)` of the reference vertices :math:`X_a` (no dof coordinate
is gathered) and the second moment is closed:

.. math::
    D_p = \sum_a N_a r_a r_a^T = J M(X_p) J^T, \qquad
    M = \mathrm{diag}(X) - X X^T \ \text{(tetrahedron)}, \qquad
    M = \mathrm{diag}(X_i (1 - X_i)) \ \text{(hexahedron)},

so APIC's rotation (:func:`fempm.kernels.affine.carried`) costs one 3x3 solve and no loop over
the dofs; :math:`C_p = L_p` (degree 1).
"""

from __future__ import annotations

from fempm.kernels.affine import APIC, THIN
from fempm.kernels.choice import INLINE
from fempm.kernels.shape import AVAILABLE

__all__: list[str] = []

if AVAILABLE:
    from numba import njit

    __all__ += ["add_affine3", "carried3", "jacobian3", "offset3", "spin3"]

    @njit(inline=INLINE)
    def jacobian3(K, c):  # pragma: no cover - compiled
        """The Jacobian of cell ``c`` (9 entries, row by row): the inverse of ``K[c]``."""
        a, b, e = K[c, 0, 0], K[c, 0, 1], K[c, 0, 2]
        d, f, g = K[c, 1, 0], K[c, 1, 1], K[c, 1, 2]
        h, i, k = K[c, 2, 0], K[c, 2, 1], K[c, 2, 2]
        c00, c01, c02 = f * k - g * i, e * i - b * k, b * g - e * f
        inv = 1.0 / (a * c00 + d * c01 + h * c02)
        return (c00 * inv, c01 * inv, c02 * inv, (g * h - d * k) * inv, (a * k - e * h) * inv, (e * d - a * g) * inv,
                (d * i - f * h) * inv, (b * h - a * i) * inv, (a * f - b * d) * inv)

    @njit(inline=INLINE)
    def offset3(a, X0, X1, X2, j, hexa):  # pragma: no cover - compiled
        r""":math:`r_a = J (X_a - X)` of vertex ``a`` (DOLFINx's order) from the reference point
        (X0, X1, X2), ``j`` the Jacobian's 9 entries."""
        if hexa:
            e0, e1, e2 = float(a & 1), float((a >> 1) & 1), float((a >> 2) & 1)
        else:
            e0, e1, e2 = 1.0 if a == 1 else 0.0, 1.0 if a == 2 else 0.0, 1.0 if a == 3 else 0.0
        d0, d1, d2 = e0 - X0, e1 - X1, e2 - X2
        return (j[0] * d0 + j[1] * d1 + j[2] * d2, j[3] * d0 + j[4] * d1 + j[5] * d2,
                j[6] * d0 + j[7] * d1 + j[8] * d2)

    @njit(inline=INLINE)
    def carried3(C, spin, p, X, j, hexa, kind):  # pragma: no cover - compiled
        r"""The matrix P2G maps (9 entries, row by row): ``C[p]``, plus for APIC the rotation
        :math:`W(\omega)` that gives it the stored spin at the present :math:`D_p = J M J^T`,
        :math:`(\mathrm{tr} D_p\, I - D_p)\, \omega = s_p - \epsilon : (C_p D_p)^T` (none where
        that operator is singular against the cell's size: a particle on a vertex or an edge)."""
        c00, c01, c02 = C[p, 0, 0], C[p, 0, 1], C[p, 0, 2]
        c10, c11, c12 = C[p, 1, 0], C[p, 1, 1], C[p, 1, 2]
        c20, c21, c22 = C[p, 2, 0], C[p, 2, 1], C[p, 2, 2]
        if kind != APIC:
            return c00, c01, c02, c10, c11, c12, c20, c21, c22
        X0, X1, X2 = X
        if hexa:
            m00, m11, m22, m01, m02, m12 = X0 - X0 * X0, X1 - X1 * X1, X2 - X2 * X2, 0.0, 0.0, 0.0
        else:
            m00, m11, m22, m01, m02, m12 = X0 - X0 * X0, X1 - X1 * X1, X2 - X2 * X2, -X0 * X1, -X0 * X2, -X1 * X2
        # T = J M, D = T J^T (symmetric)
        t00 = j[0] * m00 + j[1] * m01 + j[2] * m02
        t01 = j[0] * m01 + j[1] * m11 + j[2] * m12
        t02 = j[0] * m02 + j[1] * m12 + j[2] * m22
        t10 = j[3] * m00 + j[4] * m01 + j[5] * m02
        t11 = j[3] * m01 + j[4] * m11 + j[5] * m12
        t12 = j[3] * m02 + j[4] * m12 + j[5] * m22
        t20 = j[6] * m00 + j[7] * m01 + j[8] * m02
        t21 = j[6] * m01 + j[7] * m11 + j[8] * m12
        t22 = j[6] * m02 + j[7] * m12 + j[8] * m22
        d00 = t00 * j[0] + t01 * j[1] + t02 * j[2]
        d01 = t00 * j[3] + t01 * j[4] + t02 * j[5]
        d02 = t00 * j[6] + t01 * j[7] + t02 * j[8]
        d11 = t10 * j[3] + t11 * j[4] + t12 * j[5]
        d12 = t10 * j[6] + t11 * j[7] + t12 * j[8]
        d22 = t20 * j[6] + t21 * j[7] + t22 * j[8]
        # the spin C D carries: eps : (C D)^T, (C D)_jk = sum_q c_jq d_qk
        s0 = spin[p, 0] - ((c20 * d01 + c21 * d11 + c22 * d12) - (c10 * d02 + c11 * d12 + c12 * d22))
        s1 = spin[p, 1] - ((c00 * d02 + c01 * d12 + c02 * d22) - (c20 * d00 + c21 * d01 + c22 * d02))
        s2 = spin[p, 2] - ((c10 * d00 + c11 * d01 + c12 * d02) - (c00 * d01 + c01 * d11 + c02 * d12))
        tr = d00 + d11 + d22
        a00, a11, a22, a01, a02, a12 = tr - d00, tr - d11, tr - d22, -d01, -d02, -d12  # A = tr I - D
        q00, q01, q02 = a11 * a22 - a12 * a12, a02 * a12 - a01 * a22, a01 * a12 - a02 * a11  # adj(A)
        q11, q12, q22 = a00 * a22 - a02 * a02, a01 * a02 - a00 * a12, a00 * a11 - a01 * a01
        det = a00 * q00 + a01 * q01 + a02 * q02
        scale = 0.0
        for e in range(9):
            scale += j[e] * j[e]
        if not det > THIN * scale * scale * scale:
            return c00, c01, c02, c10, c11, c12, c20, c21, c22
        inv = 1.0 / det
        w0 = (q00 * s0 + q01 * s1 + q02 * s2) * inv
        w1 = (q01 * s0 + q11 * s1 + q12 * s2) * inv
        w2 = (q02 * s0 + q12 * s1 + q22 * s2) * inv
        return c00, c01 - w2, c02 + w1, c10 + w2, c11, c12 - w0, c20 - w1, c21 + w0, c22

    @njit(inline=INLINE)
    def add_affine3(out, i, col, N, q, mc, r):  # pragma: no cover - compiled
        r"""``out[i, col:col+3]`` += :math:`N (q + M C r)` (``q`` = :math:`M v`, ``mc`` =
        :math:`M C`, 9 entries row by row, ``r`` the dof's offset)."""
        r0, r1, r2 = r
        out[i, col] += N * (q[0] + mc[0] * r0 + mc[1] * r1 + mc[2] * r2)
        out[i, col + 1] += N * (q[1] + mc[3] * r0 + mc[4] * r1 + mc[5] * r2)
        out[i, col + 2] += N * (q[2] + mc[6] * r0 + mc[7] * r1 + mc[8] * r2)

    @njit(inline=INLINE)
    def spin3(j, X, u, vg):  # pragma: no cover - compiled
        r"""APIC's spin :math:`\sum_a N_a r_a \times v_a = \sum_q J_q \times u_q - (J X) \times v_g`
        of the nodal velocities :math:`v_a`, with :math:`r_a = J (X_a - X)`, the Jacobian's
        columns :math:`J_q`, ``u`` = :math:`u_q = \sum_a N_a X_{aq} v_a` (9 entries, q by q) and
        ``vg`` = :math:`v_g = \sum_a N_a v_a`."""
        X0, X1, X2 = X
        y0 = j[0] * X0 + j[1] * X1 + j[2] * X2  # J X
        y1 = j[3] * X0 + j[4] * X1 + j[5] * X2
        y2 = j[6] * X0 + j[7] * X1 + j[8] * X2
        s0 = y2 * vg[1] - y1 * vg[2]  # -(J X) x v_g
        s1 = y0 * vg[2] - y2 * vg[0]
        s2 = y1 * vg[0] - y0 * vg[1]
        for q in range(3):
            c0, c1, c2 = j[q], j[3 + q], j[6 + q]
            w0, w1, w2 = u[3 * q], u[3 * q + 1], u[3 * q + 2]
            s0 += c1 * w2 - c2 * w1
            s1 += c2 * w0 - c0 * w2
            s2 += c0 * w1 - c1 * w0
        return s0, s1, s2
