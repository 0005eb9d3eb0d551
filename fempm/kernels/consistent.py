r"""Compiled pieces of the consistent mass for point particles on affine degree-1 cells
(:class:`fempm.stepping.consistent.ConsistentNodalMass` drives them; :func:`fempm.transfer.cell_blocks`
and :func:`fempm.transfer.consistent_mass_matrix` are their reference).

:func:`cell_mass` (one particle pass): the local matrices, the diagonal and the occupancy,

.. math::
    A_c = \sum_{p \in c} M_p N(x_p) N(x_p)^T, \qquad
    d_i = \sum_p M_p N_{ip}^2, \qquad n_c = \#\{p \in c\}.

:func:`coo_values` (one pass over the cells of a fixed sparsity): the COO values of the matrix
on the dofs ``keep`` (the others get an identity row, and right-hand side 0, so they solve to
0 as if removed), with the rows and columns of ``lump`` dofs moved to the diagonal: every
:math:`m_{ij}`, :math:`i \ne j`, with :math:`i` or :math:`j` lumped is added to :math:`m_{ii}`.
"""

from __future__ import annotations

import functools

import numpy as np

from fempm.kernels.shape import AVAILABLE, CELLS, is_affine, space_of

__all__ = ["cell_mass"]

if AVAILABLE:
    from numba import njit

    from fempm.kernels.shape import shape

    @njit(cache=True)
    def coo_values(blocks, pattern_cells, cell_dofs, keep, lump, slot, identity_dofs, diagonal_slot,
                   out):  # pragma: no cover
        """``out`` = the values of the sparsity's entries: entry (row ``a``, column ``b``) of the
        block ``blocks[q]`` of cell ``pattern_cells[q]`` adds to ``out[slot[q, a, b]]``, and 1
        to the diagonal entry ``out[diagonal_slot[r]]`` of each dof ``identity_dofs[r]`` not
        kept."""
        out[:] = 0.0
        k = blocks.shape[1]
        for q in range(len(pattern_cells)):
            c = pattern_cells[q]
            for a in range(k):
                i = cell_dofs[c, a]
                if not keep[i]:
                    continue
                for b in range(k):
                    j = cell_dofs[c, b]
                    v = blocks[q, a, b]
                    if a == b or lump[i] or lump[j]:
                        out[slot[q, a, a]] += v
                    elif keep[j]:
                        out[slot[q, a, b]] += v
        for r in range(len(identity_dofs)):
            if not keep[identity_dofs[r]]:
                out[diagonal_slot[r]] += 1.0

    @njit(cache=True)
    def coo_entry_values(entries, rows, cols, row_diagonal, keep, lump, identity_dofs, diagonal_slot,
                         out):  # pragma: no cover
        """:func:`coo_values` from the summed entries of the sparsity (``entries[e]`` of row dof
        ``rows[e]``, column dof ``cols[e]``, its row's diagonal entry ``row_diagonal[e]``) instead
        of the cells' blocks."""
        out[:] = 0.0
        for e in range(len(entries)):
            i = rows[e]
            if not keep[i]:
                continue
            j = cols[e]
            v = entries[e]
            if i == j or lump[i] or lump[j]:
                out[row_diagonal[e]] += v
            elif keep[j]:
                out[e] += v
        for r in range(len(identity_dofs)):
            if not keep[identity_dofs[r]]:
                out[diagonal_slot[r]] += 1.0

    @njit(cache=True)
    def eigenvalue_bounds(B, out):  # pragma: no cover
        r"""Bounds of the smallest eigenvalue of each symmetric positive semi-definite ``B[n]``
        (k, k) from its :math:`LDL^T` pivots :math:`d_i`: ``out[n] = (min d_i, \prod d_i /
        \mathrm{tr}(B)^{k-1})``, an upper and a lower bound (a pivot
        :math:`d_i = 1 / (B_i^{-1})_{ii}` of the leading block :math:`B_i` is at least its
        smallest eigenvalue, hence at least :math:`B`'s, and
        :math:`\lambda_{min} \ge \det B / \lambda_{max}^{k-1}`). A pivot at or below 0 gives
        (that pivot, 0)."""
        n, k = B.shape[0], B.shape[1]
        L = np.empty((k, k))
        d = np.empty(k)
        for c in range(n):
            lo, det, tr = np.inf, 1.0, 0.0
            for i in range(k):
                tr += B[c, i, i]
                for j in range(i + 1):
                    v = B[c, i, j]
                    for m in range(j):
                        v -= L[i, m] * L[j, m] * d[m]
                    if j < i:
                        L[i, j] = v / d[j]
                    else:
                        d[i] = v
                lo = min(lo, d[i])
                if d[i] <= 0.0:
                    break
                det *= d[i]
            out[c, 0] = lo
            out[c, 1] = det / tr ** (k - 1) if lo > 0.0 else 0.0

    @njit(cache=True)
    def adjacency(dofs, nd):  # pragma: no cover
        """The cells of each dof, (start (nd + 1,), cells): dof ``i``'s cells are
        ``cells[start[i]:start[i + 1]]`` (CSR of the transposed ``dofs`` (cells, k))."""
        n, k = dofs.shape
        start = np.zeros(nd + 1, dtype=np.int64)
        for c in range(n):
            for a in range(k):
                start[dofs[c, a] + 1] += 1
        for i in range(nd):
            start[i + 1] += start[i]
        fill = start[:-1].copy()
        adjacent = np.empty(n * k, dtype=np.int32)
        for c in range(n):
            for a in range(k):
                i = dofs[c, a]
                adjacent[fill[i]] = c
                fill[i] += 1
        return start, adjacent

    @njit(cache=True)
    def propagate(blocks, dofs, determined, pending, tol, unsure, start, adjacent):  # pragma: no cover
        """The cell-by-cell determination of :func:`fempm.transfer.mass_span.singular_dofs` on one rank,
        in place, to its fixed point: a ``pending`` cell whose Jacobi-scaled block restricted to
        its undetermined dofs has its smallest eigenvalue clearly above ``tol`` (pivot bounds,
        :func:`eigenvalue_bounds`, by a factor 2; one undetermined dof: its diagonal above 0)
        makes them ``determined`` and is done; cells sharing a newly determined dof (``start``,
        ``adjacent``: :func:`adjacency` of ``dofs``) are tested again (a worklist).
        ``unsure[c]``: the last test of cell ``c`` was not clear either way (for an exact
        eigenvalue test)."""
        n, k = dofs.shape
        queue = np.empty(n, dtype=np.int32)  # a ring of at most n queued cells
        queued = np.zeros(n, dtype=np.bool_)
        head, size = 0, 0
        for c in range(n):
            if pending[c]:
                queue[size] = c
                queued[c] = True
                size += 1
        B = np.empty((1, k, k))
        bounds = np.empty((1, 2))
        scale = np.empty(k)
        free = np.empty(k, dtype=np.bool_)
        while size > 0:
            c = queue[head]
            head = head + 1 if head + 1 < n else 0
            size -= 1
            queued[c] = False
            unsure[c] = False
            if not pending[c]:
                continue
            undetermined, untouched = 0, False
            for a in range(k):
                free[a] = not determined[dofs[c, a]]
                if free[a]:
                    undetermined += 1
                    diag = blocks[c, a, a]
                    untouched |= diag <= 0.0
                    scale[a] = 1.0 / np.sqrt(diag) if diag > 0.0 else 0.0
            if undetermined == 0:  # nothing left to determine: done without a test
                pending[c] = False
                continue
            if untouched:
                continue
            if undetermined > 1:  # one dof with a positive diagonal: its scaled block is 1
                for a in range(k):
                    for b in range(k):
                        if free[a] and free[b]:
                            B[0, a, b] = blocks[c, a, b] * scale[a] * scale[b]
                        else:
                            B[0, a, b] = 1.0 if a == b else 0.0
                eigenvalue_bounds(B, bounds)
                if bounds[0, 1] <= 2.0 * tol:
                    unsure[c] = bounds[0, 0] >= 0.5 * tol
                    continue
            pending[c] = False
            for a in range(k):
                i = dofs[c, a]
                if determined[i]:
                    continue
                determined[i] = True
                for q in range(start[i], start[i + 1]):
                    e = adjacent[q]
                    if pending[e] and not queued[e]:
                        t = head + size
                        queue[t if t < n else t - n] = e
                        queued[e] = True
                        size += 1

    @njit(cache=True)
    def to_system(values, col, sel, keep, out):  # pragma: no cover
        """``out[q] = values[sel[q], col]`` where ``keep[sel[q]]``, else 0: a column of a nodal
        array (parent dofs) as a vector of the system (its dofs ``sel``)."""
        for q in range(len(sel)):
            i = sel[q]
            out[q] = values[i, col] if keep[i] else 0.0

    @njit(cache=True)
    def from_system(x, sel, col, out):  # pragma: no cover
        """``out[sel[q], col] = x[q]``: a solution of the system into a nodal array."""
        for q in range(len(sel)):
            out[sel[q], col] = x[q]

    @njit(cache=True)
    def advance(a, v_old, mass, weak_max, dt, damping, v_new):  # pragma: no cover
        r""":math:`v^+ = v + \Delta t\,(a - c\, v)`, with the acceleration 0 where the mass is at
        most ``weak_max``."""
        for i in range(len(a)):
            weak = mass[i] <= weak_max
            for j in range(a.shape[1]):
                acc = 0.0 if weak else a[i, j] - damping * v_old[i, j]
                v_new[i, j] = v_old[i, j] + dt * acc


@functools.cache
def cell_mass(cell: str):
    """The particle pass of the consistent mass, compiled for one cell type:
    ``kernel(cells, X, K, cell_dofs, mass, row, blocks, diagonal, count)`` adds to ``blocks``
    (rows, k, k), ``diagonal`` (ndofs,) and ``count`` (rows,), where cell ``c`` has row
    ``row[c]``; returns the number of particles in cells without a row (-1), which it skips.
    Particles of zero mass (another body's, for one body's matrix) add nothing and are skipped."""
    D, NK, SIMPLEX = CELLS[cell]
    AFFINE = is_affine(cell)
    DEGREE, BERNSTEIN = space_of(cell)

    @njit(cache=True)
    def kernel(cells, X, K, cell_dofs, mass, row, blocks, diagonal, count):  # pragma: no cover
        N = np.empty(NK)
        G = np.empty((NK, D))
        missing = 0
        for p in range(len(cells)):
            m = mass[p]
            if m == 0.0:
                continue
            c = cells[p]
            q = row[c]
            if q < 0:
                missing += 1
                continue
            shape(X, p, K, c, SIMPLEX, AFFINE, D, NK, N, G, DEGREE, BERNSTEIN)
            count[q] += 1
            for a in range(NK):
                w = m * N[a]
                diagonal[cell_dofs[c, a]] += w * N[a]
                for b in range(NK):
                    blocks[q, a, b] += w * N[b]
        return missing

    return kernel

