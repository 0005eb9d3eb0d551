r"""P2G and G2P sums over the particles, the lumped and the consistent mass, and the nodal
centres of mass."""

from __future__ import annotations

import dolfinx
import dolfinx.fem
import dolfinx.la
import numpy as np
import numpy.typing as npt
from petsc4py import PETSc

from fempm import petsc as fpetsc
from fempm.kernels.p2g import scatter_gradients
from fempm.particles.particle_set import Particles
from fempm.transfer.basis import ParticleBasis
from fempm.transfer.centres import NodalCentres

__all__ = [
    "SUPPORT_TOL", "WEIGHTS", "SingularMassError", "cell_blocks", "consistent_mass_matrix", "lumped_mass",
    "mass_centres", "nodal_centroids", "p2g", "p2g_gradients", "particle_weights", "sum_over_ranks",
]

#: a dof is supported when its diagonal (consistent) or lumped mass exceeds this fraction
#: of the largest one
SUPPORT_TOL = 1e-14


class SingularMassError(ValueError):
    """The particles cannot determine a unique consistent projection."""


def sum_over_ranks(index_map, local: npt.NDArray) -> npt.NDArray:
    """Add the ghost contributions (ndofs, k) to their owners and update the ghosts (the
    input itself on one rank without ghosts)."""
    if index_map.num_ghosts == 0 and index_map.comm.size == 1:
        return local
    vec = dolfinx.la.vector(index_map, bs=local.shape[1])
    vec.array[:] = local.ravel()
    vec.scatter_reverse(dolfinx.la.InsertMode.add)
    vec.scatter_forward()
    return vec.array.reshape(local.shape)


def p2g(basis: ParticleBasis, weights: npt.NDArray, *, values: npt.NDArray | None = None) -> npt.NDArray:
    r""":math:`\sum_p w_p S[p, i]` summed over all ranks; (owned + ghost dofs, k), ghosts updated."""
    return sum_over_ranks(basis.index_map, basis.scatter(weights, values=values))


def nodal_centroids(basis: ParticleBasis, mass: npt.NDArray, x: npt.NDArray) -> NodalCentres:
    r"""The centre of mass of the particles as each node sees it,
    :math:`\bar x_i = \sum_p M_p N_{ip} x_p / \sum_p M_p N_{ip}` (owned + ghost dofs, d; NaN
    at nodes without mass), with the nodal masses :math:`\sum_p M_p N_{ip}`."""
    mx = p2g(basis, np.hstack([mass[:, None], mass[:, None] * x]))
    return NodalCentres(mass_centres(mx[:, 0], mx[:, 1:]), mx[:, 0])


def mass_centres(m: npt.NDArray, moments: npt.NDArray) -> npt.NDArray:
    """Nodal masses (..., n) and first mass moments (..., n, d) -> centres of mass (..., n, d),
    NaN where the mass is 0."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(m[..., None] > 0.0, moments / m[..., None], np.nan)


def p2g_gradients(basis: ParticleBasis, vectors: npt.NDArray) -> npt.NDArray:
    r""":math:`\sum_p w_p \cdot \nabla N_i(x_p)` for per-particle tensors ``vectors`` (n, k, d):
    row ``a`` of the result is :math:`\sum_p \sum_b w_{p,a b}\, G[p, i, b]` (e.g. the internal
    force with :math:`w_p = -V_p \sigma_p`); returns (owned + ghost dofs, k)."""
    return sum_over_ranks(basis.index_map, scatter_gradients(basis.dofs, basis.gradients, vectors,
                                                            basis.num_dofs_local))


WEIGHTS = ("mass", "volume")


def particle_weights(particles: Particles, weight: str) -> npt.NDArray:
    r"""The least-squares weights :math:`w_p`: the masses :math:`M_p` (per-mass fields such as
    velocity) or the volumes :math:`V_p` (per-volume fields such as stress)."""
    if weight == "mass":
        return particles.mass
    if weight == "volume":
        return particles.volume
    raise ValueError(f"unknown option weight={weight!r}; expected one of {', '.join(WEIGHTS)}")


def lumped_mass(basis: ParticleBasis, particles: Particles, weight: str = "mass") -> npt.NDArray:
    r"""The lumped nodal mass :math:`m_i = \sum_p M_p \langle N_i \rangle_p`, or with
    ``weight="volume"`` the nodal volume :math:`V_i = \sum_p V_p \langle N_i \rangle_p`.

    Args:
        basis: The basis at the particles.
        particles: The particles.
        weight: ``"mass"`` or ``"volume"``.

    Returns:
        (owned + ghost dofs,) values summed over ranks, ghosts updated.

    Note:
        Collective.
    """
    return p2g(basis, particle_weights(particles, weight))[:, 0]


def cell_blocks(basis: ParticleBasis, weights: npt.NDArray) -> tuple[npt.NDArray, npt.NDArray, npt.NDArray]:
    r"""Point particles: the cells holding particles, their dofs (nc, k) and the local matrices
    :math:`A_c = \sum_{p \in c} w_p N(x_p) N(x_p)^T` (nc, k, k), summed per cell with
    ``np.bincount``."""
    S = basis.values
    k = S.shape[1]
    contrib = weights[:, None, None] * S[:, :, None] * S[:, None, :]  # (n, k, k)
    cells, inv = np.unique(basis.cells, return_inverse=True)
    key = (inv[:, None] * (k * k) + np.arange(k * k)[None, :]).ravel()
    blocks = np.bincount(key, weights=contrib.ravel(), minlength=len(cells) * k * k).reshape(len(cells), k, k)
    return cells, np.asarray(basis.V.dofmap.list)[cells], blocks


def consistent_mass_matrix(
    basis: ParticleBasis, particles: Particles, lump: npt.NDArray[np.bool_] | None = None, weight: str = "mass",
    blocks: tuple[npt.NDArray, npt.NDArray, npt.NDArray] | None = None, weights: npt.NDArray | None = None,
) -> PETSc.Mat:
    r"""PETSc matrix :math:`m_{ij} = \sum_p M_p N_i(x_p) N_j(x_p)` (one row per scalar dof).

    With the point basis, particle contributions are summed per cell first
    (:func:`cell_blocks`, or the ``blocks`` it returned), then inserted once as COO data. For a domain-averaged basis (:mod:`fempm.transfer.domains`) the
    matrix is :math:`\bar S^T \operatorname{diag}(M) \bar S` with
    :math:`\bar S_{pi} = \langle N_i \rangle_p`, inserted per particle: the normal equations
    of the mass-weighted least-squares fit :math:`\min_F \sum_p M_p (\langle F \rangle_p - f_p)^2`.
    It couples dofs that share no cell, and it reproduces every field whose domain averages are
    the particle values (linear fields for domains centred on their particles). The average of
    the product, :math:`\sum_p M_p \langle N_i N_j \rangle_p`, does not: in 1D it misses
    :math:`\sum_p M_p f' \langle N_i (x - x_p) \rangle_p \ne 0`.

    ``lump`` (mask over owned + ghost dofs, the same on every rank that sees a dof) lumps the
    rows and columns of those dofs: every :math:`m_{ij}`, :math:`i \ne j`, with :math:`i` or
    :math:`j` lumped moves to :math:`m_{ii}`. Row sums (the lumped masses, hence the
    conservation of mass and momentum) and symmetry are kept. ``weight="volume"`` weights by
    :math:`V_p` instead of :math:`M_p` (per-volume fields); ``weights`` replaces either (one
    body's masses, zero for the others: that body's own matrix).
    """
    M = particle_weights(particles, weight) if weights is None else weights
    if basis.cells is None:  # averaged basis: a particle's dofs span several cells
        S = basis.values
        dofs, values = basis.dofs, M[:, None, None] * S[:, :, None] * S[:, None, :]
    else:
        _, dofs, values = blocks if blocks is not None else cell_blocks(basis, M)
    k = dofs.shape[1]
    rows = np.broadcast_to(dofs[:, :, None], (len(dofs), k, k))
    cols = np.broadcast_to(dofs[:, None, :], (len(dofs), k, k))
    if lump is not None:
        cols = np.where(lump[rows] | lump[cols], rows, cols)
    return fpetsc.coo_matrix(basis.index_map, rows, cols, values)
