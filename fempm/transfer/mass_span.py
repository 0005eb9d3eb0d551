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

from fempm import petsc as fpetsc
from fempm.kernels.shape import AVAILABLE
from fempm.transfer.mapping import SingularMassError, sum_over_ranks

__all__ = [
    "DENSE_LIMIT", "RANK_TOL", "check_nonsingular", "mass_ratio_estimate", "mass_ratio_ksp", "mass_ratio_rhs",
    "share_flags", "singular_dofs",
]

if AVAILABLE:
    from fempm.kernels.consistent import adjacency, eigenvalue_bounds, propagate

log = logging.getLogger("fempm")

#: relative eigenvalue (after Jacobi scaling) below which a matrix counts as singular
RANK_TOL = 1e-10
#: largest number of undetermined dofs whose mass matrix is checked densely
DENSE_LIMIT = 4000


def _nonsingular(blocks: npt.NDArray, keep: npt.NDArray[np.bool_], exact: bool = False) -> npt.NDArray[np.bool_]:
    """Whether each block restricted to its ``keep`` rows/columns is nonsingular (Jacobi-scaled
    smallest eigenvalue above RANK_TOL; ``exact``: by ``eigvalsh`` for every block); blocks with
    nothing to keep count as nonsingular."""
    diag = np.einsum("nii->ni", blocks)
    k = blocks.shape[1]
    touched = keep & (diag > 0)
    scale = np.where(touched, 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0)), 0.0)
    B = blocks * scale[:, :, None] * scale[:, None, :]
    B = np.where(keep[:, :, None] & keep[:, None, :], B, 0.0) + np.eye(k) * (~keep)[:, :, None]
    return _smallest_above(B, RANK_TOL, exact) & ~np.any(keep & ~touched, axis=1)


def _smallest_above(B: npt.NDArray, tol: float, exact: bool = False) -> npt.NDArray[np.bool_]:
    """Whether the smallest eigenvalue of each symmetric positive semi-definite ``B[n]`` exceeds
    ``tol``: decided from pivot bounds (:func:`fempm.kernels.consistent.eigenvalue_bounds`)
    where they are clear by a factor 2, by ``eigvalsh`` for the others."""
    above = np.zeros(len(B), dtype=np.bool_)
    unsure = np.ones(len(B), dtype=np.bool_)
    if AVAILABLE and len(B) and not exact:
        bounds = np.empty((len(B), 2))
        eigenvalue_bounds(np.ascontiguousarray(B), bounds)
        above = bounds[:, 1] > 2.0 * tol
        unsure = ~above & (bounds[:, 0] >= 0.5 * tol)
    if unsure.any():
        above[unsure] = np.linalg.eigvalsh(B[unsure])[:, 0] > tol
    return above


def _propagate(blocks: npt.NDArray, dofs: npt.NDArray, determined: npt.NDArray[np.bool_],
               pending: npt.NDArray[np.bool_], cells_of: tuple | None) -> None:
    """Step 2 of the module on this rank, in place, until nothing changes: compiled
    (:func:`fempm.kernels.consistent.propagate`, the cells its bounds leave unsure tested with
    ``eigvalsh``; ``cells_of``: the cells of each dof, :func:`fempm.kernels.consistent.adjacency`
    of ``dofs``), or in rounds over all pending cells without numba (``cells_of`` unused)."""
    while True:
        if AVAILABLE:
            unsure = np.zeros(len(dofs), dtype=np.bool_)
            propagate(np.ascontiguousarray(blocks), np.ascontiguousarray(dofs), determined, pending, RANK_TOL, unsure,
                      *cells_of)
            idx = np.flatnonzero(pending & unsure)
            solved = _nonsingular(blocks[idx], ~determined[dofs[idx]], exact=True)
        else:
            idx = np.flatnonzero(pending)
            solved = _nonsingular(blocks[idx], ~determined[dofs[idx]])
        newly = np.zeros_like(determined)
        newly[dofs[idx[solved]].ravel()] = True
        pending[idx[solved]] = False
        if not np.any(newly & ~determined):
            return
        determined |= newly


def share_flags(index_map, flags: npt.NDArray[np.bool_]) -> npt.NDArray[np.bool_]:
    """A dof flag (owned + ghost) set on any rank, set on every rank that sees the dof."""
    return sum_over_ranks(index_map, flags[:, None].astype(np.float64))[:, 0] > 0


def check_nonsingular(index_map, num_particles: int, active: npt.NDArray[np.bool_], lump: npt.NDArray[np.bool_] | None,
                      blocks: tuple[npt.NDArray, npt.NDArray, npt.NDArray] | None,
                      cells_of: tuple | None = None) -> None:
    """Raise :class:`fempm.transfer.SingularMassError` when the consistent mass on the ``active``
    dofs (``lump`` ones lumped) is singular: more coupled dofs than ``num_particles`` (global),
    or, given the point particles' cell ``blocks`` (:func:`fempm.transfer.cell_blocks`), a null
    direction (:func:`singular_dofs`; ``cells_of``: kept :func:`fempm.kernels.consistent.adjacency`
    of the blocks' dofs). Collective."""
    n = index_map.size_local
    coupled = active[:n] & (~lump[:n] if lump is not None else True)
    nactive = index_map.comm.allreduce(int(np.count_nonzero(coupled)))
    if num_particles < nactive:  # rank(m) = rank(S) <= number of particles
        raise SingularMassError(
            f"the consistent mass matrix is singular: {num_particles} particles "
            f"support {nactive} coupled dofs (its rank is at most the number of particles); "
            "seed more particles per cell or use a lower degree"
        )
    if blocks is None:
        return
    null, undetermined = singular_dofs(index_map, blocks, active, lump, cells_of)
    if null:
        raise SingularMassError(
            f"the consistent mass matrix is singular: the particles determine no unique value on "
            f"{null} direction(s) of the {undetermined} dofs that no cell's particles span "
            "(coincident or collinear particles, or too few per cell for this space); seed "
            "particles that span each cell, use lump_below, lumped mass or a lower degree"
        )


def singular_dofs(imap, blocks: tuple[npt.NDArray, npt.NDArray, npt.NDArray], active: npt.NDArray[np.bool_],
                  lump: npt.NDArray[np.bool_] | None = None, cells_of: tuple | None = None) -> tuple[int, int]:
    """(number of null directions of the consistent mass on the ``active`` dofs, number of dofs
    left undetermined after the cell tests), both global, from the per-cell matrices ``blocks``
    of :func:`fempm.transfer.cell_blocks`, dofs of the ``imap`` (owned + ghost); ``cells_of``:
    the cells of each dof (:func:`fempm.kernels.consistent.adjacency` of the blocks' dofs),
    made here if None. Collective; point basis only."""
    comm = imap.comm
    n_local = imap.size_local + imap.num_ghosts
    cells, dofs, blocks = blocks
    determined = ~active[:n_local].copy()
    if lump is not None:
        determined |= lump[:n_local]
    pending = np.ones(len(cells), dtype=bool)
    if AVAILABLE and cells_of is None:  # once for the rounds over ranks
        cells_of = adjacency(np.ascontiguousarray(dofs), n_local)
    while True:
        before = determined.copy()
        _propagate(blocks, dofs, determined, pending, cells_of)
        if comm.size == 1 or not comm.allreduce(int(np.count_nonzero(determined & ~before))):
            break  # one rank: _propagate reached the fixed point
        determined = share_flags(imap, determined)
    undetermined = ~determined[: imap.size_local]
    n_und = comm.allreduce(int(np.count_nonzero(undetermined)))
    if n_und == 0:
        return 0, 0
    null = _sparse_null_count(imap, dofs, blocks, ~determined)
    if null is not None:
        return null, n_und
    if n_und > DENSE_LIMIT:  # without MUMPS: the dense test only up to DENSE_LIMIT dofs
        log.warning("fempm: %d dofs (%s) share the particles of several cells; without MUMPS their part of the "
                    "consistent mass matrix is not tested for singularity beyond the particle count", n_und,
                    "more than the dense test takes")
        return 0, n_und
    return _dense_null_count(imap, cells, dofs, blocks, ~determined), n_und


def _sparse_null_count(imap, dofs, blocks, undetermined) -> int | None:
    """Null directions of the mass matrix restricted to the ``undetermined`` dofs: the null
    pivots of a MUMPS factorization of it, Jacobi-scaled (:func:`fempm.petsc.null_pivots`);
    None without MUMPS. Collective."""
    rows = np.broadcast_to(dofs[:, :, None], blocks.shape)
    cols = np.broadcast_to(dofs[:, None, :], blocks.shape)
    sel = undetermined[rows] & undetermined[cols]
    A = fpetsc.coo_matrix(imap, rows[sel], cols[sel], blocks[sel])
    index = fpetsc.owned_index_set(imap, undetermined[: imap.size_local])
    S = A.createSubMatrix(index, index)
    d = S.getDiagonal()
    d.array[:] = 1.0 / np.sqrt(np.where(d.array > 0, d.array, 1.0))
    S.diagonalScale(d, d)
    try:
        return fpetsc.null_pivots(S)
    finally:
        for obj in (A, S, d, index):
            obj.destroy()


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


def mass_ratio_ksp(comm, iterations: int, rowsum: bool = True):
    r"""The KSP of the estimate of :math:`\lambda_{min}(M_L^{-1} M_C)`: ``iterations`` CG steps
    preconditioned by the row sums (the lumped mass; ``rowsum=False``, a basis with negative
    values: the sums of the entries' magnitudes, which are the row sums where the entries are
    not negative) that record their Lanczos coefficients (options prefix ``fempm_mass_ratio_``).
    With the diagonal instead, P2 Lagrange's vertex rows (a fifth of the Bernstein row sums on
    triangles) made the consistent step 2.4 times the Bernstein one of the same space, and
    Cook's membrane at h = 2 unstable at CFL 0.4."""

    ksp = fpetsc.create_ksp(comm, "fempm_mass_ratio_", {
        "ksp_type": "cg", "pc_type": "jacobi", "ksp_rtol": 1e-14,
        "pc_jacobi_type": "rowsum" if rowsum else "rowl1",
        "ksp_max_it": iterations, "ksp_norm_type": "preconditioned"})
    ksp.setComputeSingularValues(True)
    return ksp


def mass_ratio_estimate(ksp, A, b, x) -> float:
    """The smallest Ritz value of the preconditioned ``A`` from the CG run of ``ksp``
    (:func:`mass_ratio_ksp`) on the right-hand side ``b``, clipped to [0, 1] (``x`` is work)."""
    ksp.setOperators(A)
    x.set(0.0)
    ksp.solve(b, x)
    smax, smin = ksp.computeExtremeSingularValues()
    return float(min(max(smin, 0.0), 1.0))


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
