r"""Implied particle basis functions (docs/particle_basis.md).

The particle-to-grid map of fempm takes particle values :math:`f_p` to grid values
:math:`F_i = \sum_p \psi_{ip} f_p`, so the grid field is

.. math::
    F(x) = \sum_i F_i N_i(x) = \sum_p f_p \Phi_p(x), \qquad
    \Phi_p(x) = \sum_i \psi_{ip} N_i(x),

with :math:`v_{ip} = \langle N_i \rangle_p` (point value or domain average) and

* option 1, lumped: :math:`\psi_{ip} = M_p v_{ip} / \sum_q M_q v_{iq}` (eq. 16.31),
* option 2, consistent: :math:`\psi = m^{-1} V^T \operatorname{diag}(M)`,
  :math:`m = V^T \operatorname{diag}(M) V` (eq. 16.30), the mass-weighted pseudo-inverse of
  :math:`V = [v_{pi}]` when :math:`m` is invertible.

:math:`\Phi_p` is the projection of the particle data :math:`f_q = \delta_{pq}` (property
(xiv)); :func:`particle_basis_functions` computes it so, as DOLFINx Functions.
:func:`dense_operator` and :func:`psi` build the same maps as dense arrays for small studies
(one rank), including the Moore-Penrose pseudo-inverse when :math:`m` is singular (fewer
particles than dofs).
"""

from __future__ import annotations

import dolfinx
import numpy as np
import numpy.typing as npt

from fempm.particles.particle_set import Particles
from fempm.transfer.basis import ParticleBasis
from fempm.transfer.projection import Projector

__all__ = ["OPTIONS", "dense_operator", "partially_lumped_psi", "particle_basis_functions", "psi"]

OPTIONS = {"lumped": "option 1", "consistent": "option 2"}


def particle_basis_functions(
    V: dolfinx.fem.FunctionSpace, particles: Particles, ids: npt.ArrayLike, *, option: str = "lumped",
    domain=None, petsc_options: dict | None = None, lump_below: float = 0.0,
) -> list[dolfinx.fem.Function]:
    r""":math:`\Phi_p` for the particles with global ids ``ids`` (collective): the projection
    (``option`` "lumped" or "consistent") of the data that is 1 at particle ``p`` and 0 at the
    others. Scalar ``V``; ``domain`` and ``lump_below`` (consistent option) as in
    :class:`fempm.transfer.Projector`."""
    if option not in OPTIONS:
        raise ValueError(f"unknown option option={option!r}; expected one of {', '.join(OPTIONS)}")
    if V.dofmap.index_map_bs != 1:
        raise ValueError("particle basis functions live in a scalar space")
    proj = Projector(V, particles, mass=option, domain=domain, petsc_options=petsc_options,
                     petsc_options_prefix="fempm_particle_basis_", lump_below=lump_below)
    out = []
    for pid in np.atleast_1d(np.asarray(ids)):
        u = proj.project((particles.ids == pid).astype(np.float64))
        u.name = f"Phi_{int(pid)}"
        out.append(u)
    return out


def dense_operator(V: dolfinx.fem.FunctionSpace, particles: Particles, domain=None, *, gradients: bool = False):
    r"""Dense :math:`V_{pi} = \langle N_i \rangle_p` (n, ndofs) with rows in the order of the
    particle ids, and with ``gradients`` also :math:`\langle \nabla N_i \rangle_p` (n, ndofs, d).
    For small problems on one rank."""
    if particles.comm.size > 1:
        raise ValueError("dense particle operators are for one rank (use particle_basis_functions under MPI)")
    b = ParticleBasis(V, particles, gradients=gradients, domain=domain)
    n, nd = len(particles), b.num_dofs_local
    order = np.argsort(particles.ids)
    rows = np.broadcast_to(np.arange(n)[:, None], b.dofs.shape)
    S = np.zeros((n, nd))
    np.add.at(S, (rows, b.dofs), b.values)
    if not gradients:
        return S[order]
    d = b.gradients.shape[2]
    G = np.zeros((n, nd, d))
    np.add.at(G, (rows, b.dofs), b.gradients)
    return S[order], G[order]


def psi(S: npt.NDArray, mass: npt.NDArray, option: str) -> npt.NDArray:
    r""":math:`\psi_{ip}` (ndofs, n) of option 1 (lumped) or 2 (consistent; the weighted
    pseudo-inverse :math:`(M^{1/2} V)^+ M^{1/2}`, which is :math:`m^{-1} V^T M` when
    :math:`m` is invertible). Dofs no particle touches get zero rows."""
    if option == "lumped":
        m = S.T @ mass
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(m[:, None] > 0, (S * mass[:, None]).T / m[:, None], 0.0)
    if option == "consistent":
        w = np.sqrt(mass)
        touched = np.flatnonzero(np.abs(S).sum(axis=0) > 0)
        out = np.zeros((S.shape[1], S.shape[0]))
        out[touched] = np.linalg.pinv(w[:, None] * S[:, touched], rcond=1e-12) * w[None, :]
        return out
    raise ValueError(f"unknown option option={option!r}; expected one of {', '.join(OPTIONS)}")


def partially_lumped_psi(S: npt.NDArray, mass: npt.NDArray, lump_below: float) -> npt.NDArray:
    r""":math:`\psi = \tilde m^{-1} V^T M` with the consistent mass whose rows and columns of
    dofs with lumped mass below ``lump_below`` times the largest are lumped (off-diagonal
    entries moved to the diagonal; :func:`fempm.transfer.consistent_mass_matrix`); the
    pseudo-inverse when that matrix is singular."""
    m = S.T @ mass
    touched = np.flatnonzero(m > 0)
    St = S[:, touched]
    mc = St.T @ (mass[:, None] * St)
    lump = m[touched] < lump_below * m.max()
    off = lump[:, None] | lump[None, :]
    np.fill_diagonal(off, False)
    moved = np.where(off, mc, 0.0).sum(axis=1)
    mc = np.where(off, 0.0, mc)
    mc[np.diag_indices_from(mc)] += moved
    out = np.zeros((S.shape[1], S.shape[0]))
    out[touched] = np.linalg.lstsq(mc, (St * mass[:, None]).T, rcond=None)[0]  # pseudo-inverse if singular
    return out
