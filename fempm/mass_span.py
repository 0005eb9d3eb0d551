r"""Is the consistent mass matrix singular? A test from the particles' span, not their count.

With point particles, :math:`m_{ij} = \sum_p M_p N_i(x_p) N_j(x_p)` is singular on the
supported dofs exactly when a nonzero field :math:`u = \sum_i u_i N_i` vanishes at every
particle. Counting particles misses coincident or collinear ones (400 particles at one point
determine one value, not four). The test here is exact and cheap where it matters:

1. *Spanned cells.* A cell whose particles determine every polynomial of the cell's space
   (its local matrix :math:`A_c = \sum_{p \in c} M_p N N^T` is nonsingular, judged after
   Jacobi scaling) forces :math:`u = 0` on all its dofs. Dofs of spanned cells, lumped dofs
   (diagonal rows) and dofs held at zero are *determined*.
2. *Propagation.* A cell whose particles determine its remaining undetermined dofs (the block
   of :math:`A_c` on those dofs is nonsingular) makes them determined too; repeated over ranks
   until nothing changes.
3. *The rest, exactly.* If undetermined dofs remain, :math:`m` restricted to them (a null
   vector of :math:`m` can only live there) is assembled densely on every rank (at most
   :data:`DENSE_LIMIT` dofs) and its Jacobi-scaled eigenvalues are counted: any below
   :data:`RANK_TOL` makes the matrix singular.

Every step is sufficient (no false alarms) and the last one is exact, so the result does not
depend on the number of ranks. Domain-averaged bases (GIMP, CPDI) couple dofs of several cells
per particle; for them only the count test of :class:`fempm.transfer.Projector` applies.
"""

from __future__ import annotations

import logging

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.transfer import sum_over_ranks

log = logging.getLogger("fempm")

#: relative eigenvalue (after Jacobi scaling) below which a matrix counts as singular
RANK_TOL = 1e-10
#: largest number of undetermined dofs whose mass matrix is checked densely
DENSE_LIMIT = 4000


def _nonsingular(blocks: npt.NDArray, keep: npt.NDArray[np.bool_]) -> npt.NDArray[np.bool_]:
    """Whether each block restricted to its ``keep`` rows/columns is nonsingular (Jacobi-scaled
    smallest eigenvalue above RANK_TOL); blocks with nothing to keep count as nonsingular."""
    diag = np.einsum("nii->ni", blocks)
    k = blocks.shape[1]
    touched = keep & (diag > 0)
    scale = np.where(touched, 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0)), 0.0)
    B = blocks * scale[:, :, None] * scale[:, None, :]
    B = np.where(keep[:, :, None] & keep[:, None, :], B, 0.0) + np.eye(k) * (~keep)[:, :, None]
    lam = np.linalg.eigvalsh(B)[:, 0] if len(B) else np.zeros(0)
    return (lam > RANK_TOL) & ~np.any(keep & ~touched, axis=1)


def _share(index_map, flags: npt.NDArray[np.bool_]) -> npt.NDArray[np.bool_]:
    """A dof flag (owned + ghost) set on any rank, set on every rank that sees the dof."""
    return sum_over_ranks(index_map, flags[:, None].astype(np.float64))[:, 0] > 0


def singular_dofs(basis, blocks: tuple[npt.NDArray, npt.NDArray, npt.NDArray], active: npt.NDArray[np.bool_],
                  lump: npt.NDArray[np.bool_] | None = None) -> tuple[int, int]:
    """(number of null directions of the consistent mass on the ``active`` dofs, number of dofs
    left undetermined after the cell tests), both global, from the per-cell matrices ``blocks``
    of :func:`fempm.transfer.cell_blocks`. Collective; point basis only."""
    imap = basis.index_map
    comm = imap.comm
    n_local = imap.size_local + imap.num_ghosts
    cells, dofs, blocks = blocks
    determined = ~active[:n_local].copy()
    if lump is not None:
        determined |= lump[:n_local]
    pending = np.ones(len(cells), dtype=bool)
    while True:
        keep = ~determined[dofs[pending]]
        solved = _nonsingular(blocks[pending], keep)
        newly = np.zeros(n_local, dtype=bool)
        newly[dofs[pending][solved].ravel()] = True
        newly &= ~determined
        idx = np.flatnonzero(pending)
        pending[idx[solved]] = False
        changed = comm.allreduce(int(np.count_nonzero(newly)))
        if not changed:
            break
        determined = _share(imap, determined | newly)
    undetermined = ~determined[: imap.size_local]
    n_und = comm.allreduce(int(np.count_nonzero(undetermined)))
    if n_und == 0:
        return 0, 0
    if n_und > DENSE_LIMIT:
        log.warning("fempm: %d dofs are not determined cell by cell; the consistent mass matrix is not "
                    "checked for singularity beyond the particle count", n_und)
        return 0, n_und
    return _dense_null_count(imap, cells, dofs, blocks, ~determined), n_und


def _dense_null_count(imap, cells, dofs, blocks, undetermined) -> int:
    """Null directions of the mass matrix restricted to the ``undetermined`` dofs, assembled
    densely from every rank's cell blocks (global dof numbers) and counted on every rank."""
    comm = imap.comm
    rows = np.broadcast_to(dofs[:, :, None], blocks.shape)
    cols = np.broadcast_to(dofs[:, None, :], blocks.shape)
    sel = undetermined[rows] & undetermined[cols]
    l2g = imap.local_to_global(np.arange(len(undetermined), dtype=np.int32))
    local = np.stack([l2g[rows[sel]].astype(np.float64), l2g[cols[sel]].astype(np.float64), blocks[sel]])
    allr = np.concatenate(comm.allgather(local), axis=1) if comm.size > 1 else local
    g, inv = np.unique(allr[:2].astype(np.int64), return_inverse=True)
    inv = inv.reshape(2, -1)
    A = np.zeros((len(g), len(g)))
    np.add.at(A, (inv[0], inv[1]), allr[2])
    d = np.sqrt(np.diag(A))
    d = np.where(d > 0, d, 1.0)
    lam = np.linalg.eigvalsh(A / d[:, None] / d[None, :])
    return int(np.count_nonzero(lam <= RANK_TOL * max(lam.max(initial=0.0), 1.0)))


def mass_ratio_rhs(V, owned_mask: npt.NDArray[np.bool_]) -> npt.NDArray:
    """A pseudo-random vector over the owned dofs where ``owned_mask`` holds, a hash of each
    dof's coordinates: the same value for the same dof whatever the partition (the
    stable-step estimate then does not depend on the number of ranks)."""
    if not V.element.interpolation_ident:  # Bernstein: the positions of the Lagrange dofs (same dof layout)
        import dolfinx.fem

        V = dolfinx.fem.functionspace(V.mesh, ("Lagrange", V.element.basix_element.degree))
    x = V.tabulate_dof_coordinates()[: len(owned_mask)][owned_mask]
    span = np.ptp(V.mesh.geometry.x, axis=0) if len(V.mesh.geometry.x) else np.ones(3)
    top = V.mesh.comm.allreduce(float(span.max(initial=0.0)), op=MPI.MAX) or 1.0
    q = np.round(x / (1e-7 * top)).astype(np.int64)
    h = (q[:, 0] * 73856093) ^ (q[:, 1] * 19349663) ^ (q[:, 2] * 83492791)
    h = (h * 2654435761) & 0xFFFFFFFF
    return h / 2.0**32 - 0.5
