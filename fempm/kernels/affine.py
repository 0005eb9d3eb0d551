r"""The affine transfers' per-particle pieces, inlined into the compiled P2G and G2P passes
(:mod:`fempm.kernels.lumped`); their numpy reference is :mod:`fempm.transfer.affine`.

With the particle's basis :math:`N_a`, its dofs' coordinates :math:`x_a` and offsets
:math:`r_a = x_a - x_p`:

* :func:`second_moment`: :math:`D_p = \sum_a N_a r_a r_a^T` (returns its trace);
* :func:`carried`: the matrix P2G maps, TPIC's :math:`C_p`, APIC's :math:`C_p + W(\omega_p)` that
  carries the stored spin at the present :math:`D_p`;
* :func:`g2p_affine`: what G2P stores, APIC's :math:`C_p = L_p + (B_p - L_p D_p) D_p^{-1}`
  (:math:`L_p` on degree-1 affine cells and where :math:`D_p` is too thin) and its spin
  :math:`\epsilon : B_p^T`, TPIC's :math:`L_p`, of the updated grid velocity.

Codes of the affine transfers (:attr:`fempm.transfer.transfers.Transfer.kind`): :data:`APIC` 1,
:data:`TPIC` 2.
"""

from __future__ import annotations

from fempm.kernels.choice import INLINE
from fempm.kernels.shape import AVAILABLE

__all__ = ["APIC", "NONE", "THICK", "THIN", "TPIC"]

NONE, APIC, TPIC = 0, 1, 2

#: a D_p whose trace (in 3D: whose spin operator's determinant) is at most this share of the
#: particle's largest |r_ip|^2 (its cube) carries no spin (a particle on a vertex, or on an edge in 3D)
THIN = 1e-12
#: APIC's G2P takes C_p = L_p where det D_p is at most this share of (tr D_p / d)^d (about 4 or 27
#: times the ratio of its smallest and largest eigenvalues: a particle on a node or near a cell's
#: edge, where D_p cannot be inverted)
THICK = 1e-6

if AVAILABLE:
    import numpy as np
    from numba import njit

    @njit(inline=INLINE)
    def det(A, D):  # pragma: no cover - compiled
        """The determinant of the (D, D) matrix ``A``, D <= 3."""
        if D == 1:
            return A[0, 0]
        if D == 2:
            return A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
        return (A[0, 0] * (A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1]) - A[0, 1] * (A[1, 0] * A[2, 2] - A[1, 2] * A[2, 0])
                + A[0, 2] * (A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]))

    @njit(inline=INLINE)
    def inverse(A, D, out):  # pragma: no cover - compiled
        """``out`` = the inverse of the (D, D) matrix ``A`` (D <= 3) by cofactors."""
        a = det(A, D)
        if D == 1:
            out[0, 0] = 1.0 / a
        elif D == 2:
            out[0, 0], out[0, 1] = A[1, 1] / a, -A[0, 1] / a
            out[1, 0], out[1, 1] = -A[1, 0] / a, A[0, 0] / a
        else:
            for i in range(3):
                for j in range(3):
                    i1, i2 = (j + 1) % 3, (j + 2) % 3
                    j1, j2 = (i + 1) % 3, (i + 2) % 3
                    out[i, j] = (A[i1, j1] * A[i2, j2] - A[i1, j2] * A[i2, j1]) / a

    @njit(inline=INLINE)
    def offsets(geo, p, sizes, R, J):  # pragma: no cover - compiled
        r"""``R[a]`` = :math:`x_a - x_p` of particle p's dofs (``geo`` = (X, K, c, cell_dofs, xi,
        x), ``sizes`` = (D, NK, SIMPLEX, FROM_K)): with ``FROM_K`` (degree 1 on affine cells)
        :math:`J (X_a - X_p)` of the reference vertices and :math:`J = K_c^{-1}`, no gather of the
        dofs' coordinates; else ``xi[dof] - x[p]``."""
        X, K, c, cell_dofs, xi, x = geo
        D, NK, SIMPLEX, FROM_K = sizes
        if not FROM_K:
            for a in range(NK):
                i = cell_dofs[c, a]
                for j in range(D):
                    R[a, j] = xi[i, j] - x[p, j]
            return
        inverse(K[c], D, J)
        for a in range(NK):
            for j in range(D):
                t = 0.0
                for i in range(D):
                    ref = (1.0 if a == i + 1 else 0.0) if SIMPLEX else float((a >> i) & 1)
                    t += J[j, i] * (ref - X[p, i])
                R[a, j] = t

    @njit(inline=INLINE)
    def second_moment(N, R, D, NK, Dm):  # pragma: no cover - compiled
        r""":math:`D_p = \sum_a N_a r_a r_a^T` into ``Dm`` of the offsets ``R``; returns (its trace,
        the largest :math:`|r_a|^2`)."""
        for j in range(D):
            for k in range(D):
                Dm[j, k] = 0.0
        top = 0.0
        for a in range(NK):
            w = N[a]
            r2 = 0.0
            for j in range(D):
                rj = R[a, j]
                r2 += rj * rj
                for k in range(D):
                    Dm[j, k] += w * rj * R[a, k]
            top = max(top, r2)
        tr = 0.0
        for j in range(D):
            tr += Dm[j, j]
        return tr, top

    @njit(inline=INLINE)
    def spin_of(B, D, s):  # pragma: no cover - compiled
        r"""``s`` = :math:`\epsilon : B^T` (1 entry in 2D, 3 in 3D)."""
        if D == 2:
            s[0] = B[1, 0] - B[0, 1]
        elif D == 3:
            s[0] = B[2, 1] - B[1, 2]
            s[1] = B[0, 2] - B[2, 0]
            s[2] = B[1, 0] - B[0, 1]

    @njit(inline=INLINE)
    def carried(C, spin, p, Dm, tr, scale, D, KIND, work):  # pragma: no cover - compiled
        r"""The matrix P2G maps into ``work[0]``: ``C[p]`` (TPIC), plus for APIC the rotation
        :math:`W(\omega)` with :math:`\epsilon : ((C + W) D_p)^T` = ``spin[p]`` (none where
        :math:`D_p` is too thin against ``scale``, the particle's largest :math:`|r_a|^2`)."""
        Cu, CD, A, Ai, miss, om = work
        for j in range(D):
            for k in range(D):
                Cu[j, k] = C[p, j, k]
        if KIND != APIC or D == 1:
            return
        for j in range(D):
            for k in range(D):
                t = 0.0
                for q in range(D):
                    t += C[p, j, q] * Dm[q, k]
                CD[j, k] = t
        spin_of(CD, D, miss)
        if D == 2:
            if tr > THIN * scale:
                w = (spin[p, 0] - miss[0]) / tr
                Cu[0, 1] -= w
                Cu[1, 0] += w
            return
        for j in range(3):
            miss[j] = spin[p, j] - miss[j]
            for k in range(3):
                A[j, k] = (tr if j == k else 0.0) - Dm[j, k]
        if not det(A, 3) > THIN * scale * scale * scale:
            return
        inverse(A, 3, Ai)
        for j in range(3):
            om[j] = Ai[j, 0] * miss[0] + Ai[j, 1] * miss[1] + Ai[j, 2] * miss[2]
        Cu[0, 1] -= om[2]
        Cu[1, 0] += om[2]
        Cu[0, 2] += om[1]
        Cu[2, 0] -= om[1]
        Cu[1, 2] -= om[0]
        Cu[2, 1] += om[0]

    @njit(inline=INLINE)
    def affine_work(D, NK):  # pragma: no cover - compiled
        """Scratch arrays of a pass: :math:`D_p`, :func:`g2p_affine`'s, :func:`carried`'s and
        :func:`offsets`' (R, J)."""
        return (np.empty((D, D)), (np.empty((D, D)), np.empty((D, D)), np.empty((D, D)), np.empty((D, D)), np.empty(3)),
                (np.empty((D, D)), np.empty((D, D)), np.empty((3, 3)), np.empty((3, 3)), np.empty(3), np.empty(3)),
                (np.empty((NK, D)), np.empty((D, D))))

    @njit(inline=INLINE)
    def carried_at(N, R, state, p, sizes, Dm, work):  # pragma: no cover - compiled
        """:func:`carried` of particle p at its present :math:`D_p` (of the offsets ``R``;
        ``state`` = (C, spin), ``sizes`` = (D, NK, KIND)) into ``work[0]``."""
        C, spin = state
        D, NK, KIND = sizes
        tr, top = second_moment(N, R, D, NK, Dm) if KIND == APIC else (0.0, 0.0)
        carried(C, spin, p, Dm, tr, top, D, KIND, work)

    @njit(inline=INLINE)
    def add_momentum(at, mom, particle, sizes, affine):  # pragma: no cover - compiled
        r"""``mom[i, o + j]`` += :math:`N_a M_p (v_p + C r_a)_j` over the particle's dofs (``at`` =
        (N, cell_dofs, c, o), ``particle`` = (v, p, M_p), ``sizes`` = (D, NK), ``affine`` = (C,
        the offsets R, with it or not))."""
        N, cell_dofs, c, o = at
        v, p, m = particle
        D, NK = sizes
        Cu, R, with_affine = affine
        for a in range(NK):
            i = cell_dofs[c, a]
            for j in range(D):
                t = v[p, j]
                if with_affine:
                    for k in range(D):
                        t += Cu[j, k] * R[a, k]
                mom[i, o + j] += N[a] * (m * t)

    @njit(inline=INLINE)
    def flagged(flags, cell_dofs, c, NK):  # pragma: no cover - compiled
        """Whether a dof of cell ``c`` is flagged (``affine_cutoff``'s weak nodes)."""
        for a in range(NK):
            if flags[cell_dofs[c, a]]:
                return True
        return False

    @njit(inline=INLINE)
    def velocity_moment(at, v, R, D, NK, B):  # pragma: no cover - compiled
        r""":math:`B = \sum_a N_a v_a r_a^T` of the nodal velocity ``v`` (``at`` as
        :func:`g2p_affine`'s)."""
        N, cell_dofs, c, o = at
        for j in range(D):
            for k in range(D):
                B[j, k] = 0.0
        for a in range(NK):
            i = cell_dofs[c, a]
            w = N[a]
            for j in range(D):
                vj = w * v[i, o + j]
                for k in range(D):
                    B[j, k] += vj * R[a, k]

    @njit(inline=INLINE)
    def g2p_affine(at, velocities, R, p, Lp, sizes, outputs, work):  # pragma: no cover - compiled
        r"""What G2P stores at particle p (``at`` = (N, cell_dofs, c, o): its basis, its cell and
        the nodal columns from ``o``; ``R`` its dofs' offsets; ``sizes`` = (D, NK, KIND, CLOSED))
        of the grid velocities ``velocities`` = (v, v_spin, apart): the matrix of ``v``, given
        its velocity gradient ``Lp``, into ``out[p]`` and APIC's spin, of ``v_spin`` when
        ``apart`` (``affine_cutoff``: the updated velocity) else of ``v``, into ``spin[p]``
        (``outputs`` = (out, spin))."""
        v, v_spin, apart = velocities
        D, NK, KIND, CLOSED = sizes
        out, spin = outputs
        B, Dm, BL, Di, s = work
        for j in range(D):
            for k in range(D):
                out[p, j, k] = Lp[j, k]
        if KIND != APIC:
            return
        velocity_moment(at, v, R, D, NK, B)
        if apart:  # (BL as scratch)
            velocity_moment(at, v_spin, R, D, NK, BL)
            spin_of(BL, D, s)
        else:
            spin_of(B, D, s)
        for j in range(spin.shape[1]):
            spin[p, j] = s[j]
        if CLOSED:
            return
        tr = second_moment(at[0], R, D, NK, Dm)[0]
        if not det(Dm, D) > THICK * (tr / D) ** D:
            return
        inverse(Dm, D, Di)
        for j in range(D):  # BL = B - L D
            for k in range(D):
                t = B[j, k]
                for q in range(D):
                    t -= Lp[j, q] * Dm[q, k]
                BL[j, k] = t
        for j in range(D):
            for k in range(D):
                t = 0.0
                for q in range(D):
                    t += BL[j, q] * Di[q, k]
                out[p, j, k] += t
