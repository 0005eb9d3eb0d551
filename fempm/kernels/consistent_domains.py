r"""The consistent mass of particle domains in compiled passes
(:class:`fempm.stepping.consistent.DomainConsistentMass`; the numpy reference is
:func:`fempm.transfer.mapping.consistent_mass_matrix` on the averaged basis).

With a domain-averaged basis :math:`\bar S_{pi} = \langle N_i \rangle_p` the matrix is
:math:`m_{ij} = \sum_p M_p \bar S_{pi} \bar S_{pj}`: a particle couples the dofs of every cell its
samples lie in, which need not share a cell. The samples of a particle lie in its cell's vertex
star (the cells sharing a vertex with it; those beyond are located elsewhere and the step goes to
the numpy grid), so each cell's *star dofs* (:func:`star_dofs`, the dofs of its vertex star,
sorted, padded with the last) hold every dof its particles reach: with the star dofs as the
cells' dofs, the kept sparsity and values of :class:`fempm.stepping.mass_systems.ConsistentSystems`
take the matrix, each particle adding to the entries of its pairs of dofs.

* :func:`star_dofs`: the star dofs of every cell, (cells, S);
* :func:`domain_cell_mass`: the particle pass adding :math:`M_p \bar S_p \bar S_p^T` to the
  matrix's entries (the slots of the particles' cells over their star dofs: the pairs kept,
  :mod:`fempm.stepping.mass_sparsity`), :math:`\sum_p M_p \bar S_{pi}^2` to the diagonal and
  counting the particles per cell; returns the particles in cells without a block, those with a
  sample dof outside their cell's star dofs and those that reached a pair not kept.
"""

from __future__ import annotations

import functools

import numpy as np
import numpy.typing as npt

from fempm.kernels.shape import AVAILABLE, CELLS, is_affine

__all__ = ["domain_cell_mass", "star_dofs"]

if AVAILABLE:
    from numba import njit

    from fempm.kernels.samples import particle_basis

    @njit(cache=True)
    def _star_dofs(c2v, v_offsets, v_cells, cell_dofs, num_cells, width):  # pragma: no cover - compiled
        n, k = cell_dofs.shape
        out = np.empty((num_cells, width), dtype=np.int32)
        size = np.zeros(num_cells, dtype=np.int64)
        for c in range(num_cells):
            m = 0
            for vi in range(c2v.shape[1]):
                v = c2v[c, vi]
                for t in range(v_offsets[v], v_offsets[v + 1]):
                    e = v_cells[t]
                    for a in range(k):
                        i = cell_dofs[e, a]
                        seen = False
                        for b in range(m):
                            if out[c, b] == i:
                                seen = True
                                break
                        if not seen:
                            if m < width:
                                out[c, m] = i
                            m += 1
            size[c] = m
            if m <= width:
                out[c, :m].sort()
                for b in range(m, width):
                    out[c, b] = out[c, m - 1]
        return out, size


def star_dofs(star, cell_dofs: npt.NDArray[np.int32]) -> npt.NDArray[np.int32]:
    """The sorted dofs of the vertex star of every cell of ``star`` (its cells: the local ones,
    owned and ghost, :class:`fempm.kernels.bundles.Star`), padded with the last: (cells, S)."""
    c2v, v_offsets, v_cells, _ = star
    num_cells = len(c2v)
    width = 2 * cell_dofs.shape[1]
    while True:
        out, size = _star_dofs(c2v, v_offsets, v_cells, cell_dofs, num_cells, width)
        most = int(size.max(initial=1))
        if most <= width:
            return np.ascontiguousarray(out[:, :most])
        width = most


@functools.cache
def domain_cell_mass(cell: str, grad_from_values: bool, corners: bool):
    """The particle pass of the domains' consistent mass for one cell type and kind of samples
    (as :func:`fempm.kernels.samples.kernels_for`): ``kernel(cells, samples, mass, star, row,
    slot, entries, diagonal, count, wide)`` adds :math:`M_p \bar S_{pa} \bar S_{pb}` to the
    matrix's ``entries`` (nnz + 1,) at ``slot[row[c], a, b]`` over the star dofs ``star`` (cells,
    S) of each particle's cell ``c``, to ``diagonal`` (ndofs,) and ``count`` (rows,). A pair not
    kept has the last slot (:func:`fempm.stepping.mass_sparsity.entries`): its particle's row is
    marked in ``wide`` (rows,). Returns (particles in cells without a row, particles with a
    sample dof outside their cell's star dofs, both skipped; particles that reached a pair not
    kept). Particles of zero mass add nothing."""
    D, NK, SIMPLEX = CELLS[cell]
    AFFINE = is_affine(cell)

    @njit(cache=True, error_model="numpy")  # (python's: a zero test at each division, 1.6x the pass)
    def kernel(cells, samples, mass, star, row, slot, entries, diagonal, count, wide):  # pragma: no cover - compiled
        sc, cell_dofs = samples.sc, samples.cell_dofs
        Q = sc.shape[1]
        S = star.shape[1]
        N, G, cs = np.empty(NK), np.empty((NK, D)), np.empty(Q, np.int32)
        W, GW, R, Ri = np.empty((Q, NK)), np.empty((Q, NK, D)), np.empty((D, D)), np.empty((D, D))
        Sbar = np.zeros(S)
        used = np.empty(S, dtype=np.int64)
        listed = np.zeros(S, dtype=np.bool_)
        local = np.full(len(diagonal), -1, dtype=np.int64)  # dof -> its index in the current cell's star dofs
        current = -1
        missing, outside, widened = 0, 0, 0
        last = len(entries) - 1  # the slot of the pairs not kept
        for p in range(len(cells)):
            m = mass[p]
            if m == 0.0:
                continue
            c = cells[p]
            q = row[c]
            if q < 0:
                missing += 1
                continue
            if c != current:  # (the particles sorted by cell: a few cells a pass)
                if current >= 0:
                    for t in range(S):
                        local[star[current, t]] = -1
                for t in range(S - 1, -1, -1):  # the first of repeated (padding) dofs
                    local[star[c, t]] = t
                current = c
            ncell = particle_basis(p, samples, SIMPLEX, AFFINE, D, NK, grad_from_values, corners,
                                    (N, G, cs, W, GW, R, Ri))
            nused = 0
            out = False
            for k in range(ncell):
                for a in range(NK):
                    lo = local[cell_dofs[cs[k], a]]
                    if lo < 0:
                        out = True
                        break
                    if not listed[lo]:
                        listed[lo] = True
                        used[nused] = lo
                        nused += 1
                    Sbar[lo] += W[k, a]
                if out:
                    break
            if out:
                outside += 1
                for t in range(nused):
                    Sbar[used[t]], listed[used[t]] = 0.0, False
                continue
            count[q] += 1
            reached = False
            for t in range(nused):
                a = used[t]
                wa = m * Sbar[a]
                diagonal[star[c, a]] += wa * Sbar[a]
                for u in range(nused):
                    b = used[u]
                    e = slot[q, a, b]
                    reached |= e == last
                    entries[e] += wa * Sbar[b]
            if reached:
                wide[q] = True
                widened += 1
            for t in range(nused):
                Sbar[used[t]], listed[used[t]] = 0.0, False
        return missing, outside, widened

    return kernel
