r"""FMPM(k): Nairn's approximate inverse of the full (consistent) mass matrix.

With the particle-to-node matrix :math:`S_{pi} = \langle N_i \rangle_p`, particle weights
:math:`M = \operatorname{diag}(M_p)`, the lumped mass :math:`m = \operatorname{diag}(S^T M 1)`
and the consistent mass :math:`M_C = S^T M S`, the lumped P2G map is
:math:`S^+ = m^{-1} S^T M` and :math:`M_C = m\, S^+ S`. With :math:`A = I - S^+ S`,
:math:`M_C^{-1} = \sum_{l \ge 0} A^l m^{-1}`; FMPM(k) keeps the first k terms,

.. math::
    M_k^{-1} = \sum_{l=0}^{k-1} (I - m^{-1} M_C)^l\, m^{-1}, \qquad
    M_k^{-1} M_C = I - (I - m^{-1} M_C)^k,

which is k steps of Richardson's iteration :math:`x \leftarrow x + m^{-1}(b - M_C x)` from
:math:`x = 0`: the first step is the lumped solve (k = 1 is the PIC-like lumped map), every
further step one G2P and one P2G sweep (:math:`M_C x = S^T M (S x)`, no matrix assembled).
Every step keeps the grid momentum, :math:`1^T m\, x_k = 1^T b`, because
:math:`1^T m (I - m^{-1} M_C) = m^T - 1^T M_C = 0` (rows of :math:`M_C` sum to :math:`m`).
Velocity conditions hold on every increment (constrained dofs stay 0). For a non-negative
basis the eigenvalues :math:`\mu` of :math:`m^{-1} M_C` lie in :math:`(0, 1]`, so the
error :math:`(1 - \mu)^k` shrinks monotonically with k and the explicit step needs at most a
factor :math:`1/\sqrt{k}` on the lumped one: :math:`M_k^{-1} = m^{-1/2} P(B) m^{-1/2}` with
:math:`P(\mu) = (1 - (1 - \mu)^k)/\mu \le k`. References: Nairn and Hammerquist, CMAME 377
(2021) 113667; Hammerquist and Nairn, CMAME 318 (2017) 724 (XPIC).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from fempm.transfer.mapping import p2g

__all__ = ["fmpm_solve"]


def fmpm_solve(basis, weights: npt.NDArray, lumped: npt.NDArray, b: npt.NDArray, free: npt.NDArray[np.bool_],
               order: int, full, lump: npt.NDArray[np.bool_] | None = None,
               start: npt.NDArray | None = None) -> npt.NDArray:
    r""":math:`x_k = M_k^{-1} b` on the owned dofs: ``b`` (owned + ghost dofs, k) summed over
    ranks, ``lumped`` the lumped masses, ``free`` (owned dofs, k) where a component is solved
    for (others stay 0), ``full`` a callable that turns owned values into owned + ghost values
    (ghosts updated). ``lump`` (owned dofs): rows and columns lumped as in
    :func:`fempm.transfer.consistent_mass_matrix` (their couplings moved to the diagonal):
    those dofs keep the lumped value, the others see
    :math:`M_C' x = M_C x_{\bar l} + (M_C 1_l) \odot x`. ``start`` (like ``b``): added to
    ``b`` in the first, lumped solve alone, :math:`x_1 = m^{-1}(b + s)` (the affine part of
    APIC/TPIC). Returns (owned dofs, k). Collective."""

    n = free.shape[0]

    def mc(y):  # M_C y, matrix-free: S^T W (S y)
        return p2g(basis, weights[:, None] * basis.gather(full(y)))[:n]

    inv = np.where(free, 1.0 / np.where(lumped[:n] > 0, lumped[:n], 1.0)[:, None], 0.0)
    x = inv * (b[:n] if start is None else b[:n] + start[:n])
    if order > 1 and lump is not None:
        coupled = ~lump[:, None]
        to_lumped = mc(np.repeat(lump[:, None].astype(np.float64), b.shape[1], axis=1))  # M_C 1_l
        inv = np.where(coupled, inv, 0.0)
    for _ in range(order - 1):
        if lump is None:
            Mx = mc(x)
        else:
            Mx = mc(np.where(coupled, x, 0.0)) + to_lumped * x
        x = x + inv * (b[:n] - Mx)
    return x
