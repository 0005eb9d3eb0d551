r"""The entries of the kept consistent mass systems and each cell's slots among them
(:class:`fempm.stepping.mass_systems.ConsistentSystems`).

Point particles couple the dofs of their cell: the entries are the pairs of each cell's dofs,
and entry (a, b) of cell q's block is ``slot[q, a, b]``.

A particle domain couples the dofs of every cell its samples lie in, all in its cell's vertex
star (:func:`fempm.kernels.consistent_domains.star_dofs`); the pass looks its pairs up over
the star dofs of its cell, ``slot[q, a, b]``. The pairs of the star dofs by the star dofs are
twice those the particles couple (54 % of them were exact zeros at 1e5 particles on
triangles), and each solve, the preconditioner's set-up and the values' fill read them all.
A sample's cells share a vertex with each other as long as the domains are no wider than a
cell: the entries are then a cell's own dofs by its star dofs (and the transposed pairs), the
pairs of dofs whose supports meet at a vertex. A *wide* cell, one whose particles reached a
pair beyond those, keeps its star dofs by star dofs; its pairs outside the entries have the
slot ``nnz`` (:func:`entries` returns it: one entry more to sum into and ignore), and the pass
reports the cells (``fempm.kernels.consistent_domains.domain_cell_mass``).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from fempm.transfer.mass_span import share_flags

__all__ = ["cells_around", "entries"]

#: cells whose slots are looked up at once (the (cells, S, S) int64 keys of a chunk: 100 MB at S = 32)
CHUNK = 12_000


def entries(local: npt.NDArray, width: int, num_owned: int, own: npt.NDArray | None = None,
            wide: npt.NDArray[np.bool_] | None = None) -> tuple[npt.NDArray, npt.NDArray[np.int32]]:
    """The kept entries as sorted keys ``row * width + column`` and each cell's slots.

    Args:
        local: Each pattern cell's dofs (cells, S), numbered among ``width`` sub dofs; with
            ``own``: its star dofs.
        width: The number of sub dofs (owned + ghost).
        num_owned: The owned sub dofs, whose diagonal entries are always kept (identity rows).
        own: Each pattern cell's own dofs (cells, k) with particle domains (see the module);
            None: point particles.
        wide: Per pattern cell, whether it keeps its star dofs by star dofs (domains only).

    Returns:
        (keys (nnz,) int64, sorted; slot (cells, S, S) int32: entry (a, b) of a cell's dofs,
        ``nnz`` for a pair not kept).
    """
    n, S = local.shape
    local = local.astype(np.int64)
    diagonal = np.arange(num_owned, dtype=np.int64) * (width + 1)
    if own is None:
        key = np.concatenate([(local[:, :, None] * width + local[:, None, :]).ravel(), diagonal])
        unique, slot = np.unique(key, return_inverse=True)  # the entries summed per (row, column), row-major
        return unique, slot[: n * S * S].reshape(n, S, S).astype(np.int32)
    own = own.astype(np.int64)
    star = local[wide] if wide is not None else local[:0]
    unique = np.unique(np.concatenate([(own[:, :, None] * width + local[:, None, :]).ravel(),
                                       (local[:, None, :] * width + own[:, :, None]).ravel(),
                                       (star[:, :, None] * width + star[:, None, :]).ravel(), diagonal]))
    slot = np.empty((n, S, S), dtype=np.int32)
    for lo in range(0, n, CHUNK):
        block = local[lo:lo + CHUNK]
        key = block[:, :, None] * width + block[:, None, :]
        at = np.minimum(np.searchsorted(unique, key), len(unique) - 1)
        slot[lo:lo + CHUNK] = np.where(unique[at] == key, at, len(unique))
    return unique, slot


def cells_around(cell_dofs: npt.NDArray, cells: npt.NDArray, num_dofs: int, index_map=None) -> npt.NDArray[np.int32]:
    """The cells (rows of ``cell_dofs``) sharing a dof with ``cells``, these included; with
    ``index_map``, a dof of ``cells`` on any rank (collective)."""
    near = np.zeros(num_dofs, dtype=np.bool_)
    near[cell_dofs[cells].ravel()] = True
    if index_map is not None:
        near = share_flags(index_map, near)
    return np.flatnonzero(near[cell_dofs].any(axis=1)).astype(np.int32)
