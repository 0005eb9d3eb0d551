r"""Sample points of particle domains that lie beyond a rank's ghost cells.

A particle lives in an owned cell, but the sample points of its domain (GIMP, CPDI corners)
can reach cells that are neither owned nor ghost on its rank, e.g. when the domain stretches
across a partition boundary, or across a vertex-only neighbour of the ghost layer. For such
points:

1. the rank sends them to every rank whose bounding box holds them (one ``alltoall``);
2. each receiver locates them in its *owned* cells and answers with what the particle's row
   of the basis needs: the global dofs :math:`g_a` of the cell, their owner ranks, the
   values :math:`N_a(y)` and, when asked, the physical gradients :math:`\nabla N_a(y)`;
3. the sender keeps the answer of the lowest finding rank.

The dofs that are not local (owned or ghost) on the sender become extra ghosts of an
*extended* :class:`dolfinx.common.IndexMap`: the original owned and ghost dofs keep their
local indices, the extra ghosts follow. Ghost reductions (``scatter_reverse``) and updates
(``scatter_forward``) on that map then carry the remote contributions to their owners exactly
as for ordinary ghosts. All functions here are collective.
"""

from __future__ import annotations

from dataclasses import dataclass

import basix
import dolfinx
import numpy as np
import numpy.typing as npt

from fempm.particles.location import CellLocator, lowest_finding_rank

__all__ = ["RemoteBoxRows", "RemoteRows", "extend_index_map", "remote_box_rows", "remote_rows"]

#: MPI tag of the extended index map's neighbourhood set-up
_TAG = 7411


@dataclass
class RemoteRows:
    """Basis data of remote sample points (m of them, k dofs per cell)."""

    found: npt.NDArray[np.bool_]  # (m,)
    gdofs: npt.NDArray[np.int64]  # (m, k) global dof numbers
    owners: npt.NDArray[np.int32]  # (m, k) owner rank of each dof
    N: npt.NDArray  # (m, k)
    dN: npt.NDArray | None  # (m, k, gdim)


def _width(k: int, d: int, gradients: bool) -> int:
    """Columns of a packed answer: found flag, k global dofs, k owners, k values [, k d gradients]."""
    return 1 + k * (3 + (d if gradients else 0))


def _global_rows(V, local: npt.NDArray, rank: int) -> tuple[npt.NDArray, npt.NDArray]:
    """Global numbers and owner ranks of local dofs of ``V`` (any shape)."""
    imap = V.dofmap.index_map
    gd = imap.local_to_global(local.astype(np.int32).ravel()).reshape(local.shape)
    nown = imap.size_local
    owners = np.where(local < nown, rank, np.asarray(imap.owners)[np.maximum(local - nown, 0)])
    return gd.astype(np.int64), owners.astype(np.int32)


def _answer(locator: CellLocator, element: basix.finite_element.FiniteElement, V, x: npt.NDArray,
            gradients: bool) -> npt.NDArray:
    """Rows for points ``x`` received from another rank, packed as float64 (m, :func:`_width`)."""
    cells, X = locator.locate(x)
    k = element.dim
    d = locator.mesh.geometry.dim
    out = np.zeros((len(x), _width(k, d, gradients)))
    hit = np.flatnonzero(cells >= 0)
    if len(hit) == 0:
        return out
    c, Xh = cells[hit], np.ascontiguousarray(X[hit])
    tab = element.tabulate(1 if gradients else 0, Xh)[..., 0]
    local = np.asarray(V.dofmap.list)[c]  # (h, k)
    gd, own = _global_rows(V, local, locator.mesh.comm.rank)
    cols = [np.ones((len(hit), 1)), gd.astype(np.float64), own.astype(np.float64), tab[0]]
    if gradients:
        K = locator.geometry.inverse_jacobian(c, Xh)
        cols.append((np.transpose(tab[1:], (1, 2, 0)) @ K).reshape(len(hit), k * d))
    out[hit] = np.hstack(cols)
    return out


def remote_rows(locator: CellLocator, element, V, x: npt.NDArray, gradients: bool) -> RemoteRows:
    """Basis rows at points ``x`` (m, gdim) that are not in this rank's local cells. Collective
    (call it on every rank, with ``m = 0`` where there is nothing to ask)."""
    comm = locator.mesh.comm
    k, d = element.dim, locator.mesh.geometry.dim
    sent, received = locator.send_to_candidates(x)
    answers = comm.alltoall([_answer(locator, element, V, pts, gradients) for pts in received])
    m = len(x)
    owner = lowest_finding_rank(sent, [a[:, 0] > 0 for a in answers], m)
    rows = np.zeros((m, _width(k, d, gradients)))
    for r, a in enumerate(answers):
        mine = owner[sent[r]] == r
        rows[sent[r][mine]] = a[mine]
    found = owner < comm.size
    gdofs = np.rint(rows[:, 1: 1 + k]).astype(np.int64)
    owners = np.rint(rows[:, 1 + k: 1 + 2 * k]).astype(np.int32)
    N = rows[:, 1 + 2 * k: 1 + 3 * k]
    dN = rows[:, 1 + 3 * k:].reshape(m, k, d) if gradients else None
    return RemoteRows(found, gdofs, owners, N, dN)


@dataclass
class RemoteBoxRows:
    """Integrals over the parts of boxes in cells other ranks own: rows (box, global dof, owner
    rank, :math:`\\int N`, :math:`\\int \\nabla N`) and the covered volume per box."""

    box: npt.NDArray[np.int64]
    gdofs: npt.NDArray[np.int64]
    owners: npt.NDArray[np.int32]
    N: npt.NDArray
    dN: npt.NDArray | None
    volume: npt.NDArray


def remote_box_rows(locator: CellLocator, integrator, lo: npt.NDArray, hi: npt.NDArray, gradients: bool,
                    V) -> RemoteBoxRows:
    """The integrals of :class:`fempm.transfer.box_average.BoxIntegrator` over the parts of the boxes
    ``[lo, hi]`` (m, d) that lie in cells owned by other ranks. Each box goes to the ranks
    whose owned cells' bounding box it overlaps; they integrate over their owned cells and
    answer with global dofs. Collective."""
    comm = locator.mesh.comm
    rank, size, d = comm.rank, comm.size, lo.shape[1]
    bins = integrator.bins
    mine = np.concatenate([bins.lo.min(axis=0, initial=np.inf), bins.hi.max(axis=0, initial=-np.inf)])
    extents = np.array(comm.allgather(mine))  # (size, 2 d)
    sent = [np.flatnonzero(np.all((lo <= extents[r, d:]) & (hi >= extents[r, :d]), axis=1)) if r != rank
            else np.zeros(0, dtype=np.int64) for r in range(size)]
    received = comm.alltoall([np.hstack([lo[i], hi[i]]) for i in sent])
    answers = []
    for boxes in received:
        r = integrator.integrals(boxes[:, :d], boxes[:, d:], gradients)
        gd, own = _global_rows(V, r.dofs, rank)
        cols = [r.box[:, None].astype(float), gd[:, None].astype(float), own[:, None].astype(float), r.N[:, None]]
        if gradients:
            cols.append(r.dN)
        answers.append((np.hstack(cols) if len(r.box) else np.zeros((0, 4 + (d if gradients else 0))), r.volume))
    back = comm.alltoall(answers)
    volume = np.zeros(len(lo))
    parts = []
    for r, (rows, vol) in enumerate(back):
        volume[sent[r]] += vol
        rows = rows.copy()
        rows[:, 0] = sent[r][np.rint(rows[:, 0]).astype(np.int64)] if len(rows) else rows[:, 0]
        parts.append(rows)
    rows = np.concatenate(parts) if parts else np.zeros((0, 4 + (d if gradients else 0)))
    return RemoteBoxRows(np.rint(rows[:, 0]).astype(np.int64), np.rint(rows[:, 1]).astype(np.int64),
                         np.rint(rows[:, 2]).astype(np.int32), rows[:, 3], rows[:, 4:] if gradients else None, volume)


def extend_index_map(
    index_map: dolfinx.common.IndexMap, gdofs: npt.NDArray[np.int64], owners: npt.NDArray[np.int32]
) -> tuple[dolfinx.common.IndexMap, npt.NDArray[np.int32]]:
    """``index_map`` with the global dofs ``gdofs`` that are not local added as ghosts, and the
    local indices of ``gdofs`` in the new map (same shape). Collective."""
    nloc = index_map.size_local + index_map.num_ghosts
    lg = index_map.local_to_global(np.arange(nloc, dtype=np.int32)).astype(np.int64)
    order = np.argsort(lg)
    flat = gdofs.ravel()
    pos = np.clip(np.searchsorted(lg[order], flat), 0, max(nloc - 1, 0))
    known = (lg[order][pos] == flat) if nloc else np.zeros(len(flat), dtype=bool)
    local = np.full(len(flat), -1, dtype=np.int64)
    local[known] = order[pos[known]]
    extra, first, inv = np.unique(flat[~known], return_index=True, return_inverse=True)
    local[~known] = nloc + inv
    ghosts = np.concatenate([np.asarray(index_map.ghosts, dtype=np.int64), extra])
    ghost_owners = np.concatenate([np.asarray(index_map.owners, dtype=np.int32),
                                   owners.ravel()[~known][first].astype(np.int32)])
    ext = dolfinx.common.IndexMap(index_map.comm, index_map.size_local, ghosts, ghost_owners, _TAG)
    return ext, local.reshape(gdofs.shape).astype(np.int32)
