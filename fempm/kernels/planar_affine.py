r"""The affine transfers' per-particle pieces of the scalar 2D passes (:mod:`fempm.kernels.planar`),
written out for triangles and affine quadrilaterals: the generic ones are
:mod:`fempm.kernels.affine`, the reference :mod:`fempm.transfer.affine`.

On an affine cell the offsets of the particle's dofs are
:math:`x_a - x_p = J (X_a - X_p)` with :math:`J = K_c^{-1}` and the reference vertices
:math:`X_a`, so no dof coordinate is gathered; :math:`C_p = L_p` (degree 1).
"""

from __future__ import annotations

from fempm.kernels.affine import APIC, THIN
from fempm.kernels.choice import INLINE
from fempm.kernels.shape import AVAILABLE

__all__: list[str] = []

if AVAILABLE:
    from numba import njit

    __all__ += ["add_affine", "affine_g2p2", "carried2", "jacobian2", "offsets2", "spin2"]

    @njit(inline=INLINE)
    def add_affine(out, col, dofs, values, q, mc, r, quad):  # pragma: no cover - compiled
        r"""``out[i_a, col:col+2]`` += :math:`N_a (q + M C r_a)` (``q`` = :math:`M v`, ``mc`` =
        :math:`M C` row by row, ``r`` the offsets)."""
        i0, i1, i2, i3 = dofs
        N0, N1, N2, N3 = values
        q0, q1 = q
        m00, m01, m10, m11 = mc
        r0x, r0y, r1x, r1y, r2x, r2y, r3x, r3y = r
        out[i0, col] += N0 * (q0 + m00 * r0x + m01 * r0y)
        out[i0, col + 1] += N0 * (q1 + m10 * r0x + m11 * r0y)
        out[i1, col] += N1 * (q0 + m00 * r1x + m01 * r1y)
        out[i1, col + 1] += N1 * (q1 + m10 * r1x + m11 * r1y)
        out[i2, col] += N2 * (q0 + m00 * r2x + m01 * r2y)
        out[i2, col + 1] += N2 * (q1 + m10 * r2x + m11 * r2y)
        if quad:
            out[i3, col] += N3 * (q0 + m00 * r3x + m01 * r3y)
            out[i3, col + 1] += N3 * (q1 + m10 * r3x + m11 * r3y)

    @njit(inline=INLINE)
    def jacobian2(k):  # pragma: no cover - compiled
        """The Jacobian (j00, j01, j10, j11) of a cell whose inverse Jacobian is ``k``."""
        k00, k01, k10, k11 = k
        det = k00 * k11 - k01 * k10
        return k11 / det, -k01 / det, -k10 / det, k00 / det

    @njit(inline=INLINE)
    def offsets2(X0, X1, j, simplex):  # pragma: no cover - compiled
        """(r0x, r0y, r1x, r1y, r2x, r2y, r3x, r3y): the offsets of the cell's vertices from the
        particle at reference point (X0, X1) of a cell whose Jacobian is ``j`` =
        (j00, j01, j10, j11) (r3 = 0 on a triangle)."""
        j00, j01, j10, j11 = j
        d0, d1 = -X0, -X1
        e0, e1 = 1.0 - X0, 1.0 - X1
        r0x, r0y = j00 * d0 + j01 * d1, j10 * d0 + j11 * d1
        r1x, r1y = j00 * e0 + j01 * d1, j10 * e0 + j11 * d1
        r2x, r2y = j00 * d0 + j01 * e1, j10 * d0 + j11 * e1
        if simplex:
            return r0x, r0y, r1x, r1y, r2x, r2y, 0.0, 0.0
        return r0x, r0y, r1x, r1y, r2x, r2y, j00 * e0 + j01 * e1, j10 * e0 + j11 * e1

    @njit(inline=INLINE)
    def carried2(C, spin, p, X, j, simplex, kind):  # pragma: no cover - compiled
        r"""The matrix P2G maps (c00, c01, c10, c11): ``C[p]``, plus for APIC the rotation that
        gives it the stored spin at the present :math:`D_p = \sum_a N_a r_a r_a^T`
        (:func:`fempm.kernels.affine.carried`). On an affine cell with the Jacobian ``j``
        :math:`D_p = J M(X) J^T` in closed form at the reference point ``X``:
        :math:`M = \mathrm{diag}(X) - X X^T` on the triangle, :math:`\mathrm{diag}(X_i (1 - X_i))`
        on the parallelogram."""
        c00, c01, c10, c11 = C[p, 0, 0], C[p, 0, 1], C[p, 1, 0], C[p, 1, 1]
        if kind != APIC:
            return c00, c01, c10, c11
        X0, X1 = X
        j00, j01, j10, j11 = j
        m00, m11 = X0 - X0 * X0, X1 - X1 * X1
        m01 = -X0 * X1 if simplex else 0.0
        a00, a01 = j00 * m00 + j01 * m01, j00 * m01 + j01 * m11  # J M
        a10, a11 = j10 * m00 + j11 * m01, j10 * m01 + j11 * m11
        d00, d01, d11 = a00 * j00 + a01 * j01, a00 * j10 + a01 * j11, a10 * j10 + a11 * j11
        tr = d00 + d11
        if tr > THIN * (j00 * j00 + j01 * j01 + j10 * j10 + j11 * j11):
            w = (spin[p, 0] - (c10 * d00 + c11 * d01 - c00 * d01 - c01 * d11)) / tr
            c01 -= w
            c10 += w
        return c00, c01, c10, c11

    @njit(inline=INLINE)
    def spin2(N, X, j, a, b, simplex):  # pragma: no cover - compiled
        r""":math:`\epsilon : B_p^T = \sum_a N_a (r_a \times v_a)` of the nodal velocities
        ``a`` (x components) and ``b`` (y), with :math:`r_a = J (X_a - X)`:
        :math:`\sum_q J_q \times u_q - (J X) \times v_g`, the Jacobian's columns :math:`J_q`,
        :math:`u_q = \sum_a N_a X_{aq} v_a`, :math:`v_g = \sum_a N_a v_a`."""
        N0, N1, N2, N3 = N
        a0, a1, a2, a3 = a
        b0, b1, b2, b3 = b
        j00, j01, j10, j11 = j
        X0, X1 = X
        u0x, u0y, u1x, u1y = N1 * a1, N1 * b1, N2 * a2, N2 * b2
        if not simplex:
            u0x, u0y, u1x, u1y = u0x + N3 * a3, u0y + N3 * b3, u1x + N3 * a3, u1y + N3 * b3
        gx = N0 * a0 + N1 * a1 + N2 * a2 + N3 * a3
        gy = N0 * b0 + N1 * b1 + N2 * b2 + N3 * b3
        yx, yy = j00 * X0 + j01 * X1, j10 * X0 + j11 * X1
        return (j00 * u0y - j10 * u0x) + (j01 * u1y - j11 * u1x) - (yx * gy - yy * gx)

    @njit(inline=INLINE)
    def affine_g2p2(p, geo, nodal, state, cutoff, remap, kind):  # pragma: no cover - compiled
        r"""G2P's affine state of particle p (``geo`` = (X0, X1, k, simplex, quad); ``nodal`` =
        (N, the updated grid velocity's x and y components, the gradients (g0x, g0y, ...), the
        dofs)): :math:`C_p = L_p`, APIC's spin of the updated velocity; where a dof is flagged
        below ``affine_cutoff`` (``cutoff`` = (its velocity, the flags, the second column)) the
        matrix of the cutoff's velocity; with ``remap`` (the lumped mass's MUSL) the particle's
        momenta with their affine part into ``mom`` (``state`` = (C, spin, mom, the first column,
        mass, v))."""
        X0, X1, k, simplex, quad = geo
        N4, sa, sb, g, dofs = nodal
        C, spin, mom, o, mass, v = state
        va, weak, o1 = cutoff
        i0, i1, i2, i3 = dofs
        a, b = sa, sb
        if va.shape[0] > 0 and (weak[i0] or weak[i1] or weak[i2] or (quad and weak[i3])):
            a = (va[i0, o], va[i1, o], va[i2, o], va[i3, o] if quad else 0.0)
            b = (va[i0, o1], va[i1, o1], va[i2, o1], va[i3, o1] if quad else 0.0)
        a0, a1, a2, a3 = a
        b0, b1, b2, b3 = b
        g0x, g0y, g1x, g1y, g2x, g2y, g3x, g3y = g
        j = jacobian2(k)
        C[p, 0, 0] = a0 * g0x + a1 * g1x + a2 * g2x + a3 * g3x
        C[p, 0, 1] = a0 * g0y + a1 * g1y + a2 * g2y + a3 * g3y
        C[p, 1, 0] = b0 * g0x + b1 * g1x + b2 * g2x + b3 * g3x
        C[p, 1, 1] = b0 * g0y + b1 * g1y + b2 * g2y + b3 * g3y
        if kind == APIC:
            spin[p, 0] = spin2(N4, (X0, X1), j, sa, sb, simplex)
        if remap:
            mp = mass[p]
            c00, c01, c10, c11 = carried2(C, spin, p, (X0, X1), j, simplex, kind)
            add_affine(mom, o, dofs, N4, (mp * v[p, 0], mp * v[p, 1]), (mp * c00, mp * c01, mp * c10, mp * c11),
                       offsets2(X0, X1, j, simplex), quad)
