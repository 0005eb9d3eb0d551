r"""F-bar's nodal patch sums, per particle (inlined into the passes of :mod:`fempm.kernels.fbar`
and into the P2G passes that take the averaged pressure: :mod:`fempm.kernels.lumped`,
:mod:`fempm.kernels.planar`, :mod:`fempm.kernels.solid`).

The sums of B bodies are kept in a (dofs, 2 B) array, :math:`[\sum_q V_q N_{iq} \mid \sum_q V_q
N_{iq} f_q]` per body (:mod:`fempm.stepping.fbar`); once summed over ranks, :func:`averages` turns
the second half into the nodal averages :math:`(\sum V N f)_a / (\sum V N)_a` (0 where the weight
is not positive), and a particle p of body b reads :math:`\bar f_p = \sum_a N_{ap} \bar f_a`.
(The loop over a cell's dofs is written out in each pass: through a helper taking the arrays it
took 5x as long.)

The particles touch a fraction of the dofs (a quarter in the benchmarks' column in its box), so
each pass that adds to the sums also marks the blocks of :data:`BLOCK_ROWS` rows it writes in a
``dirty`` (blocks,) uint8 array; :func:`averages` and :func:`clear_blocks` visit the marked
blocks only (and those a ghost exchange writes, ``always``), instead of every dof twice a step.
"""

from __future__ import annotations

from fempm.kernels.choice import INLINE
from fempm.kernels.shape import AVAILABLE

__all__ = ["AVAILABLE", "BLOCK_ROWS", "BLOCK_SHIFT", "add_corners", "add_node", "add_patch", "average_pressure", "averages",
           "blocks", "clear_blocks", "nodal_ratio"]

#: log2 of :data:`BLOCK_ROWS`
BLOCK_SHIFT = 4
#: the rows per block of the dirty marks (dof i is in block ``i >> BLOCK_SHIFT``)
BLOCK_ROWS = 1 << BLOCK_SHIFT


def blocks(rows: int) -> int:
    """The number of dirty-mark blocks of ``rows`` rows."""
    return (rows + BLOCK_ROWS - 1) >> BLOCK_SHIFT

if AVAILABLE:
    from numba import njit

    @njit(inline=INLINE)
    def nodal_ratio(patch, i, b, bodies):  # pragma: no cover - compiled
        r""":math:`(\sum V N f)_i / (\sum V N)_i` of body ``b`` of ``bodies`` at dof ``i`` (0 where
        the weight is not positive), of sums turned into averages by :func:`averages`."""
        return patch[i, bodies + b]

    @njit(inline=INLINE)
    def add_node(out, dirty, i, b, bodies, w, value):  # pragma: no cover - compiled
        r""":math:`w` and :math:`w f` (``value``) into body ``b``'s sums of dof ``i`` of ``out``
        (dofs, 2 B of ``bodies``), its block marked in ``dirty``: one node's share of a particle
        (:math:`w = N_a V_p`)."""
        out[i, b] += w
        out[i, bodies + b] += w * value
        dirty[i >> BLOCK_SHIFT] = 1

    @njit(inline=INLINE)
    def add_patch(out, dirty, at, b, bodies, weight, value):  # pragma: no cover - compiled
        r"""A particle of body ``b`` with ``weight`` and ``value`` into the sums ``out`` (dofs, 2 B)
        at its cell's dofs, ``at`` = (basis values N, NK, cell_dofs, its cell): :math:`N_a w` and
        :math:`N_a w f`; their blocks marked in ``dirty``."""
        N, NK, cell_dofs, c = at
        for a in range(NK):
            add_node(out, dirty, cell_dofs[c, a], b, bodies, N[a] * weight, value)

    @njit(inline=INLINE)
    def add_corners(out, dirty, at, b, weight, value, quad):  # pragma: no cover - compiled
        r""":func:`add_patch` in scalar code for a triangle or (``quad``) quadrilateral of degree 1,
        ``at`` = (its dofs i0..i3, the basis values N0..N3; the fourth on a quadrilateral only)."""
        (i0, i1, i2, i3), (N0, N1, N2, N3) = at
        bodies = out.shape[1] // 2
        add_node(out, dirty, i0, b, bodies, N0 * weight, value)
        add_node(out, dirty, i1, b, bodies, N1 * weight, value)
        add_node(out, dirty, i2, b, bodies, N2 * weight, value)
        if quad:
            add_node(out, dirty, i3, b, bodies, N3 * weight, value)

    @njit(inline=INLINE)
    def average_pressure(sigma, D, at, patch, b, bodies):  # pragma: no cover - compiled
        r"""``sigma`` (D, D) <- :math:`\sigma + (\bar p - p) I`, :math:`p = \mathrm{tr}\,\sigma / D` and
        :math:`\bar p` the pressures' patch average at the particle ``at`` = (basis values N, NK,
        cell_dofs, its cell) of body ``b``."""
        N, NK, cell_dofs, c = at
        t = 0.0
        for j in range(D):
            t += sigma[j, j]
        t = -t / D
        for a in range(NK):
            t += N[a] * nodal_ratio(patch, cell_dofs[c, a], b, bodies)
        for j in range(D):
            sigma[j, j] += t

    @njit(inline=INLINE)
    def run_end(dirty, k):  # pragma: no cover - compiled
        """The first block from ``k`` on that is not marked in ``dirty`` (or their number)."""
        while k < len(dirty) and dirty[k]:
            k += 1
        return k

    @njit(cache=True, error_model="numpy")
    def averages(patch, dirty):  # pragma: no cover - compiled
        r"""The sums' second half, in place, divided by their weights: :math:`(\sum V N f)_i /
        (\sum V N)_i`, 0 where the weight is not positive, in the blocks marked in ``dirty`` (once
        per dof, before the passes read them with :func:`nodal_ratio`); over each run of marked
        blocks, a strided loop per body (which vectorizes, where a loop over rows and bodies does
        not: 4x as long)."""
        rows, bodies = patch.shape[0], patch.shape[1] // 2
        flat, width = patch.reshape(-1), 2 * bodies
        k = 0
        while k < len(dirty):
            if not dirty[k]:
                k += 1
                continue
            e = run_end(dirty, k)
            lo, hi = width * (k << BLOCK_SHIFT), width * min(e << BLOCK_SHIFT, rows)
            for b in range(bodies):
                w, f = flat[lo + b:hi:width], flat[lo + bodies + b:hi:width]
                for i in range(len(w)):
                    m = w[i]
                    r = f[i] / m
                    f[i] = r if m > 0.0 else 0.0
            k = e

    @njit(cache=True)
    def clear_blocks(patch, dirty, always):  # pragma: no cover - compiled
        """Zero the rows of ``patch`` in the blocks marked in ``dirty``, then reset the marks to
        ``always`` (the blocks a ghost exchange writes); a slice per run of marked blocks (a
        memset: a loop over the rows takes 5x as long)."""
        flat, width = patch.reshape(-1), patch.shape[1] << BLOCK_SHIFT
        k = 0
        while k < len(dirty):
            if not dirty[k]:
                dirty[k] = always[k]
                k += 1
                continue
            e = run_end(dirty, k)
            flat[k * width:min(e * width, len(flat))] = 0.0
            dirty[k:e] = always[k:e]
            k = e
