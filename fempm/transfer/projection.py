r"""Particle-to-grid (P2G) and grid-to-particle (G2P) transfers; the Galerkin projection.

The mass-weighted least-squares fit :math:`F = \sum_j F_j N_j` of particle data :math:`f_p`
minimises :math:`\int (F - f)^2 \rho\, dV`, which with particle quadrature gives

.. math::
    \sum_j m_{ij} F_j = b_i, \qquad m_{ij} = \sum_p M_p N_i(x_p) N_j(x_p), \qquad
    b_i = \sum_p M_p f_p N_i(x_p)

*Consistent* mode assembles :math:`m_{ij}` as a PETSc matrix and
solves with KSP (CG + Jacobi by default) on the dofs that particles support. *Lumped* mode
replaces :math:`m_{ij}` by its row sum :math:`m_i = \sum_p M_p N_i(x_p)` (eqs. 16.21-16.23):
:math:`F_i = b_i / m_i`, which needs a non-negative basis (P1/Q1 or Bernstein). *FMPM(k)*
(``mass="fmpm3"`` or ``mass="fmpm", fmpm_order=3``) lies between them: the first k terms of
the series of :math:`m^{-1}`-preconditioned corrections that sums to the consistent solve
(:mod:`fempm.transfer.fmpm`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Any, Literal

import dolfinx
import dolfinx.fem
import dolfinx.la
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.abort import raise_together
from fempm.particles.location import as_points3
from fempm.particles.particle_set import Particles
from fempm.transfer.basis import ParticleBasis
from fempm.transfer.mapping import SUPPORT_TOL, p2g, particle_weights
from fempm.transfer.mass_models import MassModel, mass_model

__all__ = ["MassMode", "Projector", "interpolate", "project"]

log = logging.getLogger("fempm")

MassMode = Literal["consistent", "lumped", "fmpm"] | str  # also "fmpmK", "fmpm(K)"


def _particle_values(values: npt.ArrayLike | Callable, particles: Particles, bs: int) -> npt.NDArray:
    if callable(values):  # DOLFINx convention: f(x) with x of shape (3, n)
        values = np.asarray(values(as_points3(particles.x).T), dtype=np.float64)
        n = len(particles)
        if values.size != bs * n:
            shape = "(n,)" if bs == 1 else f"({bs}, n)"
            raise ValueError(f"the function of x returned an array of shape {values.shape} for {n} particles; the "
                             f"space has {bs} component(s) per point: return {shape} values (the DOLFINx convention, "
                             f"e.g. np.vstack([...]) of {bs} rows)")
        values = values.reshape(bs, n).T  # (n, bs)
    f = np.asarray(values, dtype=np.float64)
    f = f[:, None] if f.ndim == 1 else f.reshape(f.shape[0], int(np.prod(f.shape[1:])))
    if f.shape[0] != len(particles):
        raise ValueError(f"values have {f.shape[0]} rows for {len(particles)} particles")
    if f.shape[1] != bs:
        raise ValueError(f"values have {f.shape[1]} component(s) per particle; the space has {bs}")
    if not np.all(np.isfinite(f)):
        raise ValueError(f"{np.count_nonzero(~np.isfinite(f))} particle value(s) are not finite")
    return f


class Projector:
    r"""Projection of particle data onto ``V`` with a fixed set of particles: the
    mass-weighted least-squares fit

    .. math::
        \min_F \sum_p w_p \big(\langle F \rangle_p - f_p\big)^2,

    :math:`w_p` the particles' masses (``weight="mass"``, for per-mass fields such as velocity)
    or volumes (``"volume"``, per-volume fields such as stress). The mass (the consistent matrix
    and its KSP, or the lumped vector) is assembled once; :meth:`project` then costs one P2G and
    one solve per value component.

    With volume weights the map is the density-ratio kernel: dividing a per-volume
    :math:`\sigma_p` by :math:`\rho_p = M_p / V_p`, mapping it with the mass weights and
    multiplying the grid value by :math:`m_i / V_i` gives, lumped,
    :math:`\sigma_i = \sum_p V_p v_{ip} \sigma_p / V_i`, :math:`V_i = \sum_p V_p v_{ip}`,
    which conserves :math:`\int \sigma` where the mass-weighted map would not across a
    density jump.

    Args:
        V: The space to project onto.
        particles: The particles.
        mass: The mass model: ``"consistent"`` (the exact projection), ``"lumped"``, FMPM(k)
            (``"fmpmK"``), or a :class:`~fempm.transfer.mass_models.MassModel`.
        petsc_options_prefix: The PETSc options prefix of the consistent solve.
        petsc_options: PETSc options set under that prefix.
        basis: The particle basis, if made already (else made from ``domain``).
        exclude: (Block) dofs held at 0 (Dirichlet).
        exclude_components: ``exclude_components[c]`` lists dofs whose component ``c`` only is
            held at 0 (a slip wall normal to axis c): component c is solved on its own active
            set, the constrained least-squares fit.
        lump_below: Consistent mass: dofs whose lumped mass is below this fraction of the
            largest get lumped rows and columns (:func:`consistent_mass_matrix`), so that the
            solve does not extrapolate into nodes particles barely reach (FMPM: those dofs keep
            the lumped solve); non-negative bases only.
        domain: The particle domain, a name (``"gimp"``, ``"cpdi1"``, ... as in
            :class:`fempm.stepping.StepOptions`) or a domain object (:mod:`fempm.transfer.domains`;
            default the point).
        weight: ``"mass"`` or ``"volume"`` (see above).
        fmpm_order: The k of ``mass="fmpm"``.
        weights: Per-particle weights replacing ``weight``'s, e.g. the masses of one body and
            zeros for the others (the per-body fields of :mod:`fempm.stepping.contact`).
        lump_dofs: Consistent mass and FMPM: a mask over owned + ghost dofs whose rows are lumped
            as well (those of conditions that act node by node: contact,
            :class:`fempm.boundary.Friction`).

    Note:
        Construction and :meth:`project` are collective.

    Attributes:
        active: Mask over owned + ghost dofs that particles support; other dofs are excluded
            from the solve and set to 0.
        num_inactive: Global number of unsupported dofs (also logged).
    """

    def __init__(
        self,
        V: dolfinx.fem.FunctionSpace,
        particles: Particles,
        *,
        mass: MassMode | MassModel = "consistent",
        petsc_options_prefix: str = "fempm_projection_",
        petsc_options: dict[str, Any] | None = None,
        basis: ParticleBasis | None = None,
        exclude: npt.NDArray[np.int32] | None = None,
        exclude_components: Sequence[npt.NDArray[np.int32]] | None = None,
        lump_below: float = 0.0,
        domain=None,
        weight: str = "mass",
        fmpm_order: int | None = None,
        weights: npt.NDArray | None = None,
        lump_dofs: npt.NDArray[np.bool_] | None = None,
    ):
        self.weights = particle_weights(particles, weight) if weights is None else np.asarray(weights, dtype=np.float64)
        self.weight = weight
        self.model = model = mass_model(mass, fmpm_order)
        self.label = model.label
        self.V, self.particles = V, particles
        self.basis = basis if basis is not None else ParticleBasis(V, particles, domain=domain)
        self.num_owned = self.basis.index_map.size_local
        self.lumped: npt.NDArray | None = None
        self.grid_solve = model.grid_solve(self.basis, self.weights, particles, weight, weights is not None)
        self._find_support(exclude)
        self.lump = self._lumped_rows(lump_below, lump_dofs)
        self.exclude_components = [np.asarray(d, dtype=np.int32) for d in (exclude_components or ())]
        self.grid_solve.set_up(self.active, self.lump, self.exclude_components, self.lumped_masses,
                               petsc_options_prefix, petsc_options)
        self.row_mass = self.grid_solve.row_mass

    @property
    def iterations(self) -> list[int]:
        """The KSP iterations of the last :meth:`project`, per component (empty without a matrix)."""
        return self.grid_solve.iterations

    def _find_support(self, exclude: npt.NDArray[np.int32] | None) -> None:
        r"""The active dofs: those the particles support (as the mass model measures it,
        :meth:`fempm.transfer.grid_solves.GridSolve.support_measure`) above :data:`SUPPORT_TOL`
        of the largest, less the dofs ``exclude``. Collective."""
        comm = self.particles.comm
        measure = self.grid_solve.support_measure(self.lumped_masses)
        top = comm.allreduce(float(measure[: self.num_owned].max(initial=0.0)), op=MPI.MAX)
        self.active = measure > SUPPORT_TOL * top
        if exclude is not None:  # constrained dofs (e.g. fixed velocity): value 0, not solved for
            self.active[exclude] = False
        self.num_inactive = comm.allreduce(int(np.count_nonzero(~self.active[: self.num_owned])))
        if self.num_inactive:
            log.info("fempm: %d dof(s) without particle support excluded and set to 0", self.num_inactive)

    def _lumped_rows(self, lump_below: float, lump_dofs: npt.NDArray[np.bool_] | None) -> npt.NDArray[np.bool_] | None:
        """The dofs whose rows and columns are lumped: lumped mass below ``lump_below`` of the
        largest, and ``lump_dofs`` (a non-negative basis only: for P2 Lagrange lumping can make
        the matrix indefinite; a lumped mass has nothing to lump). Collective."""
        if not (self.model.couples_dofs and self.basis.nonnegative):
            return None
        lump = None
        if lump_below > 0.0:
            m = self.lumped_masses()
            lump = m < lump_below * self.particles.comm.allreduce(float(m[: self.num_owned].max(initial=0.0)),
                                                                  op=MPI.MAX)
        if lump_dofs is not None:
            extra = np.zeros(len(self.active), dtype=np.bool_)
            extra[: len(lump_dofs)] = lump_dofs[: len(self.active)]
            lump = extra if lump is None else lump | extra
        return lump

    def mass_ratio_min(self, iterations: int = 40) -> float:
        r"""Estimate of :math:`\lambda_{min}(M_L^{-1} M_C) \in (0, 1]` (1 for the lumped mass and FMPM).

        The critical explicit step scales as :math:`1/\omega_{max}` and
        :math:`\omega_{max}^2(M_C) \le \omega_{max}^2(M_L) / \lambda_{min}`, so the lumped-mass
        CFL step times :math:`\sqrt{\lambda_{min}}` is stable with the consistent matrix.
        Estimated from the Lanczos coefficients of ``iterations`` CG steps preconditioned by the
        lumped mass (PETSc Jacobi of type rowsum) on a pseudo-random right-hand side; for a
        basis that is not non-negative (P2 Lagrange), whose row sums can vanish, of
        :math:`\lambda_{min}(D^{-1} M_C)` with the diagonal :math:`D` instead. Ritz
        values lie inside the spectrum, so the estimate is an upper bound that tightens with
        ``iterations``; callers should keep a safety factor.

        Note:
            Collective.
        """
        return self.grid_solve.mass_ratio_min(iterations)

    def support_masses(self) -> npt.NDArray:
        r"""How much particle mass each dof sees, :math:`\sum_p M_p |\langle N_i \rangle_p|` on
        owned + ghost dofs: the lumped mass for a non-negative basis, and a positive measure of
        support where lumped masses can vanish or be negative (P2 Lagrange)."""
        if self.basis.nonnegative:
            return self.lumped_masses()
        return p2g(self.basis, self.weights, values=np.abs(self.basis.values))[:, 0]

    def lumped_masses(self) -> npt.NDArray:
        """Lumped nodal masses on owned + ghost dofs (computed once)."""
        if self.lumped is None:
            self.lumped = p2g(self.basis, self.weights)[:, 0]
        return self.lumped

    def grid_total(self, u: dolfinx.fem.Function) -> npt.NDArray:
        r"""Grid total :math:`\sum_{ij} m_{ij} F_j` (lumped: :math:`\sum_i m_i F_i`) per component,
        summed over ranks. For ``u`` the projection of :math:`f_p` it equals
        :math:`\sum_p M_p f_p` (conservation; :math:`\sum_p V_p f_p` with ``weight="volume"``);
        for ``u = 1`` the total mass (volume)."""
        F = u.x.array.reshape(-1, self.basis.bs)[: self.num_owned]
        return self.particles.comm.allreduce(self.row_mass @ F)

    def rhs(self, f: npt.NDArray) -> npt.NDArray:
        r""":math:`b_i = \sum_p M_p f_p N_i(x_p)` on owned + ghost dofs, (ndofs, bs)."""
        return p2g(self.basis, self.weights[:, None] * f)

    def project(
        self, values: npt.ArrayLike | Callable, out: dolfinx.fem.Function | None = None
    ) -> dolfinx.fem.Function:
        """Project particle values (n,) / (n, bs), or a function of x, onto ``V``."""
        bs = self.basis.bs
        f, error = None, None
        try:  # values of the wrong shape on one rank are an error on every rank
            f = _particle_values(values, self.particles, bs)
        except ValueError as e:
            error = e
        raise_together(self.particles.comm, error)
        b = self.rhs(f)
        u = out if out is not None else dolfinx.fem.Function(self.V)
        u.x.array[:] = self.solve(b)[: self.basis.num_dofs_space].ravel()
        return u

    def solve(self, b: npt.NDArray, guess: npt.NDArray | None = None, start: npt.NDArray | None = None) -> npt.NDArray:
        """Solve ``m F = b`` on the active dofs for (owned + ghost dofs, k) right-hand sides;
        returns (owned + ghost dofs, k) with ghosts updated and 0 on inactive dofs.
        ``guess`` (same shape) warm-starts the KSP; ``start`` (same shape) is a term of the
        lumped first solve alone (:meth:`fempm.transfer.grid_solves.GridSolve.solve`).

        Note:
            Collective.
        """
        return self._ghosted(self.grid_solve.solve(b, guess, self._ghosted, start))

    def _ghosted(self, F: npt.NDArray) -> npt.NDArray:
        """Owned values (owned dofs, k) -> (owned + ghost dofs, k), ghosts from their owners."""
        k = F.shape[1]
        vec = dolfinx.la.vector(self.basis.index_map, bs=k)
        vec.array[: F.size] = F.ravel()
        vec.scatter_forward()
        return vec.array.reshape(-1, k)


def project(
    V: dolfinx.fem.FunctionSpace,
    particles: Particles,
    values: npt.ArrayLike | Callable,
    *,
    mass: MassMode = "consistent",
    petsc_options_prefix: str = "fempm_projection_",
    petsc_options: dict[str, Any] | None = None,
    domain=None,
    weight: str = "mass",
    fmpm_order: int | None = None,
) -> dolfinx.fem.Function:
    r"""Galerkin (mass-weighted least-squares) projection of particle values onto ``V``.

    Solves :math:`\sum_j m_{ij} F_j = b_i` with :math:`m_{ij} = \sum_p M_p \langle N_i N_j \rangle_p`
    and :math:`b_i = \sum_p M_p f_p \langle N_i \rangle_p` (lumped: :math:`m_i = \sum_j m_{ij}`).
    A :class:`Projector` that is used once; build one to project several fields on the same
    particles.

    Args:
        V: The space to project onto (scalar, vector or tensor; Lagrange, Bernstein).
        particles: The particles carrying the values.
        values: (n,) or (n, bs) values per particle, or a function of x of shape (3, n)
            returning (bs, n) values (the DOLFINx convention).
        mass: ``"consistent"`` (the exact projection), ``"lumped"``, ``"fmpm"`` (with
            ``fmpm_order``), ``"fmpmK"`` or a :class:`fempm.transfer.mass_models.MassModel`.
        petsc_options_prefix: Options prefix of the consistent solve's KSP.
        petsc_options: PETSc options set under that prefix.
        domain: The particle domain over which the basis is averaged (a name, e.g. ``"gimp"``,
            or a :mod:`fempm.transfer.domains` object; default the point).
        weight: ``"mass"`` for per-mass fields such as velocity, ``"volume"`` for per-volume
            fields such as stress.
        fmpm_order: The FMPM order with ``mass="fmpm"``.

    Returns:
        The projection, a new ``dolfinx.fem.Function`` on ``V`` with ghosts updated.

    Raises:
        ValueError: Values of the wrong shape or not finite; a lumped mass on a basis with
            negative values.
        fempm.SingularMassError: Too few particles to determine the consistent projection.

    Note:
        Collective.
    """
    projector = Projector(
        V, particles, mass=mass, petsc_options_prefix=petsc_options_prefix, petsc_options=petsc_options,
        domain=domain, weight=weight, fmpm_order=fmpm_order,
    )
    return projector.project(values)


def interpolate(u: dolfinx.fem.Function, particles: Particles, basis: ParticleBasis | None = None) -> npt.NDArray:
    r"""G2P: the values :math:`u(x_p) = \sum_i u_i \langle N_i \rangle_p` at the particles.

    Args:
        u: A function whose ghost values are up to date (as after any DOLFINx interpolation
            or solve).
        particles: The particles.
        basis: The basis at the particles (default: point values in ``u``'s space).

    Returns:
        (n,) values for a scalar space, (n, bs) otherwise.

    Note:
        Collective when ``basis`` is None (the basis is built); else local.
    """
    basis = basis if basis is not None else ParticleBasis(u.function_space, particles)
    vals = basis.gather(u.x.array.reshape(-1, basis.bs))
    return vals[:, 0] if basis.bs == 1 else vals
