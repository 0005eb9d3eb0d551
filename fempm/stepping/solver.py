r"""The explicit MPM step (seed 002): P2G, grid update, G2P with PIC/FLIP blend, kinematics,
constitutive update, position update.

Grid equations (lumped mass :math:`m_i = \sum_p M_p N_{ip}`, or the consistent matrix):

.. math::
    m_i v_i = \sum_p M_p v_p N_{ip}, \qquad
    f_i = -\sum_p V_p \sigma_p \nabla N_{ip} + \sum_p M_p b_p N_{ip}
          + \sum_p N_{ip} \bar t_p h^{-1} V_p, \qquad
    v_i^{+} = v_i + \Delta t\, f_i / m_i .

G2P: :math:`v_p^{+} = \alpha (v_p + \sum_i N_{ip}(v_i^{+} - v_i)) + (1-\alpha) \sum_i N_{ip} v_i^{+}`,
:math:`L_p = \sum_i v_i^{+} \otimes \nabla N_{ip}`, :math:`F_p^{+} = (I + \Delta t L_p) F_p`,
:math:`V_p = J_p V_p^0`, :math:`x_p^{+} = x_p + \Delta t \sum_i N_{ip} v_i^{+}`.

Schemes: USL (stress after G2P), USF (stress from the momentum velocity before the force),
MUSL (USL, with the grid velocity re-mapped from the updated particle momenta before the
strain and position update).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import dolfinx.fem
import dolfinx.mesh
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm import kernels
from fempm.boundary.constraints import axis_slip_dofs, fixed_dofs, friction_dofs
from fempm.materials.base import identity
from fempm.meshes.cell_sizes import cell_sizes
from fempm.particles.corners import domain_geometry
from fempm.particles.particle_set import Particles
from fempm.stepping import consistent as consistent_step
from fempm.stepping import diagnostics
from fempm.stepping import lumped as lumped_step
from fempm.stepping.contact import Contact, contact_step
from fempm.stepping.contact import check_options as check_contact_options
from fempm.stepping.laws import law_stress, material_groups
from fempm.stepping.loads import (  # Loads: re-exported, scenes build it from here
    Loads,
    external_forces,
)
from fempm.stepping.options import (
    MASS_RATIO_ITERATIONS,
    MASS_RATIO_SAFETY,
    SimulationError,
    StepOptions,
)
from fempm.transfer import g2p
from fempm.transfer.basis import ParticleBasis
from fempm.transfer.centres import NodalCentres
from fempm.transfer.mapping import nodal_centroids, p2g, p2g_gradients, sum_over_ranks
from fempm.transfer.projection import Projector


@dataclass
class ExplicitSolver:
    """Explicit MPM on the vector P1 (or P2/Bernstein) space ``V`` of the particles' mesh.

    Particle state lives in ``particles.fields``: ``v`` (n, d), ``F`` (n, d, d), ``sigma``
    (n, d, d), ``volume0`` (n,), ``body`` (n,) index into ``materials``, and the reference
    positions ``X0`` (n, d) (the positions when the solver is made, unless given).

    ``compiled``: take the compiled step (:mod:`fempm.stepping.lumped`, :mod:`fempm.stepping.consistent`:
    lumped or consistent mass, point particles, a degree-1 space on an affine mesh) where it
    applies (None, the default), insist on it (True: an error where it does not apply) or never
    (False: the generic step, which is its reference). ``contact``: a
    :class:`fempm.stepping.contact.Contact`, one velocity field per particle group with frictional
    contact between them (the generic step; None: one field for all).
    """

    V: dolfinx.fem.FunctionSpace
    particles: Particles
    materials: Sequence
    bcs: Sequence = ()
    loads: Loads = field(default_factory=Loads)
    options: StepOptions = field(default_factory=StepOptions)
    t: float = 0.0
    step_count: int = 0
    compiled: bool | None = None
    contact: Contact | None = None

    def __post_init__(self):
        p = self.particles
        if self.V.mesh is not p.mesh:
            raise ValueError("the particles were made on another mesh than the velocity space's: make them on V.mesh "
                             "(fempm.create_particles(V.mesh, ...) or fempm.Particles(V.mesh, ...))")
        d = p.gdim
        n = len(p)
        f = p.fields
        f.setdefault("v", np.zeros((n, d)))
        f.setdefault("F", identity(n, d))
        f.setdefault("sigma", np.zeros((n, d, d)))
        f.setdefault("volume0", p.volume.copy())
        f.setdefault("body", np.zeros(n, dtype=np.int32))
        f.setdefault("X0", p.x.copy())  # reference positions (body forces b(X, t), error norms)
        for mat in self.materials:  # the laws' internal variables (fempm.materials.base.Internal)
            for h in getattr(mat, "history", ()):
                expected = (n, *h.shape_for(d))
                if np.shape(f.setdefault(h.name, h.allocate(n, d))) != expected:
                    raise ValueError(f"internal variable {h.name!r} of {type(mat).__name__} has shape "
                                     f"{np.shape(f[h.name])}; expected {expected}")
        self._check_fields()
        self.h_cell = cell_sizes(p.mesh)
        self.terms: Counter = Counter()  # how often each force term was assembled
        self.grid_velocity: npt.NDArray | None = None  # last step's, also the CG warm start
        self.extended_steps = 0  # steps whose particle domains reached beyond this rank's ghost cells
        self.j_range: tuple[float, float] | None = None  # global (min, max) of J after the last step
        self.mass_ratio = 1.0  # last lambda_min(M_L^-1 M_C) estimate (consistent mass)
        self._stress_space: dolfinx.fem.FunctionSpace | None = None  # tensor space of grid_stress, on first use
        self._fixed_dofs = fixed_dofs(self.bcs)
        self._slip_components = axis_slip_dofs(self.bcs, d)
        index_map = self.V.dofmap.index_map
        self.node_local_dofs = friction_dofs(self.bcs, index_map.size_local + index_map.num_ghosts)
        self._lumped_step = None
        #: some wall checks contact by position (the step then maps the nodal centres of mass)
        self.needs_positions = any(getattr(bc, "needs_positions", False) for bc in self.bcs)

    # -- helpers ------------------------------------------------------------------------------
    def _material_loop(self):
        return material_groups(self.particles.fields, self.materials)

    def stable_dt(self) -> float:
        r""":math:`\Delta t = \mathrm{CFL}\, \min_p h_{c(p)} / (c_p + |v_p|)` over all ranks: the
        lumped-mass step. With consistent mass :meth:`step` multiplies it by
        :math:`\sqrt{0.8\, \lambda_{min}(M_L^{-1} M_C)}` (1/4 in 1D and 1/16 on a full 2D Q1 grid
        with 2 particles per cell and direction), see :meth:`fempm.transfer.Projector.mass_ratio_min`."""
        p = self.particles
        f = p.fields
        rho = p.mass / p.volume
        c = np.zeros(len(p))
        for mat, idx in self._material_loop():
            c[idx] = mat.wave_speed(f["F"][idx], rho[idx])
        speed = c + np.linalg.norm(f["v"], axis=1)
        moving = ~(speed <= 0)  # particles at rest with no wave speed set no limit (NaN stays)
        local = np.min(self.h_cell[p.cells][moving] / speed[moving], initial=np.inf)
        return self.options.cfl * p.comm.allreduce(local, op=MPI.MIN)

    def _compiled_step(self):
        """The compiled step (:mod:`fempm.stepping.lumped`, :mod:`fempm.stepping.consistent`) when these
        options, space and mesh take it (made on first use, remade when the options change),
        else None."""

        if not lumped_step.supported(self):
            if self.compiled:
                raise ValueError("compiled=True needs lumped or consistent mass, point particles and a degree-1 space "
                                 "on an affine mesh (simplices, parallelograms) with numba installed")
            return None
        if self._lumped_step is None or self._lumped_step.options is not self.options:
            kind = consistent_step.ConsistentPointStep if self.options.mass_mode == "consistent" else \
                lumped_step.LumpedPointStep
            self._lumped_step = kind(self)
        return self._lumped_step

    def _apply_bcs(self, v: npt.NDArray, centroids: NodalCentres | None = None) -> None:
        """The grid conditions on ``v``, in place; walls that check contact by position
        (:attr:`fempm.boundary.Friction.needs_positions`) take ``centroids``, the step's nodal
        centres of mass and masses (:meth:`_wall_centroids`)."""
        for bc in self.bcs:
            if getattr(bc, "needs_positions", False):
                bc.apply(v, centroids)
            else:
                bc.apply(v)

    def _wall_centroids(self, basis: ParticleBasis) -> NodalCentres | None:
        """The nodal centres of mass and masses of the step for the walls that need them, else None."""
        if not self.needs_positions:
            return None
        p = self.particles
        return nodal_centroids(basis, p.mass, p.x)

    def _mass_operator(self, basis: ParticleBasis, weights: npt.NDArray | None = None,
                       lump_dofs: npt.NDArray[np.bool_] | None = None) -> Projector:
        """The step's mass (lumped, consistent or FMPM) with its constraints, on ``basis``;
        ``weights``: per-particle masses in place of the particles' (one body's mass);
        ``lump_dofs``: further dofs (owned + ghost) whose rows are lumped, besides the walls'
        (:attr:`node_local_dofs`)."""
        opts = self.options
        lumped = self.node_local_dofs
        if lump_dofs is not None:
            lumped = lump_dofs if lumped is None else lumped | lump_dofs[: len(lumped)]
        return Projector(
            self.V, self.particles, mass=opts.mass_mode, fmpm_order=opts.mass_order, basis=basis,
            petsc_options_prefix=opts.petsc_options_prefix,
            exclude=self._fixed_dofs, exclude_components=self._slip_components, lump_below=opts.lump_below,
            weights=weights, lump_dofs=lumped,
        )

    def mapped_velocity(self) -> npt.NDArray:
        """The grid velocity of the present particle state, (owned + ghost dofs, d): P2G of the
        momenta and the step's mass solve and constraints (the first stage of a step), nothing
        advanced. The grid frame at t = 0 of :func:`fempm.scene.run`."""
        basis = ParticleBasis(self.V, self.particles, gradients=False, domain=self.options.particle_domain)
        centroids = self._wall_centroids(basis)
        return self._map_velocity(basis, self._mass_operator(basis), None, centroids)[: basis.num_dofs_space]

    def _map_velocity(self, basis: ParticleBasis, mass_op: Projector, guess: npt.NDArray | None,
                      centroids: NodalCentres | None = None) -> npt.NDArray:
        """Grid velocity from the particle momenta (P2G + mass solve), constrained (``centroids``:
        the nodal centres of mass for the walls that need them)."""
        p = self.particles
        v = mass_op.solve(p2g(basis, p.mass[:, None] * p.fields["v"]), guess=guess)
        self._apply_bcs(v, centroids)
        return basis.update_ghosts(v)  # extra ghosts (remote domain samples) take their owners' values

    def _update_stress(self, L: npt.NDArray, dt: float) -> None:
        p = self.particles
        f = p.fields
        F, J = kernels.deform(f["F"], L, dt)
        nonfinite = ~np.isfinite(J)
        bad = J <= 0
        finite = J[~nonfinite]
        flags = np.array([nonfinite.any(), bad.any(), -finite.min(initial=np.inf), finite.max(initial=-np.inf)], dtype=float)
        p.comm.Allreduce(MPI.IN_PLACE, flags, op=MPI.MAX)  # one collective: both checks and the J range
        if flags[0]:
            self._fail(f"non-finite state (deformation gradient) at particle(s) {self._ids(nonfinite)}")
        if flags[1]:
            self._fail(f"inverted deformation J <= 0 at particle(s) {self._ids(bad)}")
        self.j_range = (-float(flags[2]), float(flags[3]))
        f["F"] = F
        p.volume = J * f["volume0"]
        rho = p.mass / p.volume
        for mat, idx in self._material_loop():
            f["sigma"][idx] = law_stress(mat, F[idx], L[idx], f["sigma"][idx], dt, rho[idx], f, idx)

    def _ids(self, mask):
        ids = np.concatenate(self.particles.comm.allgather(self.particles.ids[mask][:5]))
        return ids[:5].tolist()

    def _fail(self, what: str):
        raise SimulationError(f"step {self.step_count}, t = {self.t:.6g}: {what}")

    def _forces(self, basis: ParticleBasis, t: float) -> npt.NDArray:
        r"""Nodal forces :math:`f_i = \sum_p (-V_p \sigma_p \nabla N_{ip} + N_{ip} f^{ext}_p)`,
        summed over ranks; point particles in one compiled scatter (:mod:`fempm.kernels`)."""
        p = self.particles
        self._count_terms()
        fext = external_forces(self.loads, p, t)
        if basis.cells is not None and not basis.extended:
            local = kernels.nodal_forces(basis.dofs, basis.values, basis.gradients, p.volume, p.fields["sigma"],
                                         fext, basis.num_dofs_local)
            return sum_over_ranks(basis.index_map, local)
        f = p2g_gradients(basis, -p.volume[:, None, None] * p.fields["sigma"])
        if self.loads.body_force is not None or self.loads.traction is not None:
            f += p2g(basis, fext)
        return f

    def _time_step(self, stable: float, dt: float | None, dt_max: float) -> float:
        """The step: ``dt`` if given (an error above the stability limit, CFL > 1), else the
        ``stable`` one, at most ``dt_max``."""
        if dt is None:
            dt = min(stable, dt_max)
            if not np.isfinite(dt):
                raise ValueError("no stable time step: every particle is at rest and its law has wave speed 0; "
                                 "give dt or dt_max")
        elif dt > stable / self.options.cfl:
            self._fail(f"time step {dt:.3g} exceeds the stability limit {stable / self.options.cfl:.3g} (CFL > 1)")
        if not self.t + dt > self.t:  # e.g. a particle at 1e200 m/s: the stable step underflows
            self._check_finite()  # collective: names a non-finite velocity first
            self._fail(f"time step collapse: dt = {dt:.3g} does not advance t = {self.t:.6g}")
        return dt

    def _check_fields(self) -> None:
        """Every particle array has a row per particle, and the fields the step reads their
        shapes (collective)."""
        d = self.particles.gdim
        shapes = {"v": (d,), "F": (d, d), "sigma": (d, d), "volume0": (), "body": (), "X0": (d,)}
        for mat in self.materials:
            shapes.update({h.name: h.shape_for(d) for h in getattr(mat, "history", ())})
        self.particles.check_fields(shapes)

    def _check_bodies(self) -> None:
        """Every particle's body indexes a material (collective)."""
        body = self.particles.fields["body"]
        bad = (body < 0) | (body >= len(self.materials))
        if self.particles.comm.allreduce(int(np.count_nonzero(bad))):
            raise ValueError(f"particle body index outside the {len(self.materials)} material(s) at particle(s) "
                             f"{self._ids(bad)}")

    def _check_step_arguments(self, dt: float | None, dt_max: float) -> None:
        """A given ``dt`` positive and finite, ``dt_max`` positive, particles on some rank."""
        if dt is not None and not (0.0 < dt < np.inf):
            raise ValueError(f"step: dt={dt} must be a positive, finite time step (or None for the stable one)")
        if not dt_max > 0.0:
            raise ValueError(f"step: dt_max={dt_max} must be positive")
        if self.particles.num_global == 0:
            raise ValueError("step: there are no particles (the particle set is empty on every rank)")

    def _count_terms(self) -> None:
        """Count the force terms assembled this step (:attr:`terms`)."""
        self.terms["internal"] += 1
        self.terms.update(k for k in ("body_force", "traction") if getattr(self.loads, k) is not None)

    # -- the step -----------------------------------------------------------------------------
    def step(self, dt: float | None = None, *, dt_max: float = np.inf) -> float:
        """Advance one step; returns the ``dt`` used. ``dt`` defaults to the stable step
        (at most ``dt_max``); a given ``dt`` above the stability limit (CFL > 1) is an error."""
        self._check_step_arguments(dt, dt_max)
        if self.contact is not None:  # one velocity field per body (fempm.stepping.contact)
            check_contact_options(self.options)
            if self.compiled:
                raise ValueError("compiled=True: the compiled step has one velocity field; contact takes the generic step")
            return contact_step(self, dt, dt_max)
        if self.compiled is not False and self._compiled_step() is not None:
            return self._lumped_step.step(dt, dt_max)
        opts = self.options
        p = self.particles
        fld = p.fields
        basis = self._open_step()
        centroids = self._wall_centroids(basis)  # (the contact step maps each body's own)
        mass_op = self._mass_operator(basis)
        dt = self._time_step(self._stable_with([mass_op]), dt, dt_max)
        support = mass_op.support_masses()
        weak = support <= opts.mass_cutoff * p.comm.allreduce(float(support.max(initial=0.0)), op=MPI.MAX)
        v_old = self._map_velocity(basis, mass_op, self.grid_velocity, centroids)
        if opts.scheme == "USF":
            self._update_stress(g2p.velocity_gradient(basis, v_old), dt)
        f_grid = self._forces(basis, self.t)
        a = self._accelerations(mass_op, f_grid)
        if opts.damping > 0.0:
            a -= opts.damping * v_old[: len(a)]
        a[weak] = 0.0  # nodes with a tiny share of mass keep their mapped velocity, no force update
        v_new = v_old + dt * a
        self._apply_bcs(v_new, centroids)
        v_new = basis.update_ghosts(v_new)
        # G2P
        fld["v"], vp_grid, L = g2p.blend(basis, v_new, v_old, fld["v"], opts.flip)
        if opts.scheme == "MUSL":
            v_new = self._map_velocity(basis, mass_op, None, centroids)
            vp_grid, L = g2p.velocity_and_gradient(basis, v_new)
        if opts.scheme != "USF":
            self._update_stress(L, dt)
        if opts.domain == "cpdi2":
            self._move_corners(basis, basis.gather_samples(v_new), dt)
        else:
            p.x = p.x + dt * (fld["v"] if self.options.position == "particle" else vp_grid)
        self._check_finite()
        self.t += dt
        self.step_count += 1
        p.relocate()
        self.grid_velocity = v_new[: basis.num_dofs_space]
        return dt

    def _stable_with(self, mass_ops: Sequence[Projector]) -> float:
        r"""The stable step of the state with these mass operators: :meth:`stable_dt` (lumped),
        times :math:`\sqrt{0.8\, \lambda_{min}}` (the smallest over the operators) with consistent
        mass, over :math:`\sqrt{k}` with FMPM(k) (:math:`\|M_k^{-1} m\| \le k`, :mod:`fempm.transfer.fmpm`);
        with lumped forces the lumped step."""
        opts = self.options
        stable = self.stable_dt()
        if opts.mass == "consistent" and not opts.lumped_forces:  # omega_max^2 <= omega_L^2 / lambda_min
            self.mass_ratio = min((op.mass_ratio_min(MASS_RATIO_ITERATIONS) for op in mass_ops), default=1.0)
            stable *= np.sqrt(MASS_RATIO_SAFETY * self.mass_ratio)
        elif opts.mass_mode == "fmpm" and not opts.lumped_forces:
            stable /= np.sqrt(opts.mass_order)
        return stable

    def _accelerations(self, mass_op: Projector, f_grid: npt.NDArray) -> npt.NDArray:
        """Nodal accelerations from the forces: the mass solve, or with ``lumped_forces`` the
        lumped division on the operator's active dofs."""
        if self.options.mass_mode != "lumped" and self.options.lumped_forces:
            m = mass_op.lumped_masses()
            return np.where(mass_op.active[:, None], f_grid / np.where(m > 0, m, 1.0)[:, None], 0.0)
        return mass_op.solve(f_grid)

    def _open_step(self) -> ParticleBasis:
        """The checks that open a generic step, and its particle basis (values and gradients)."""
        self._check_fields()
        self._check_finite()
        self._check_bodies()
        basis = ParticleBasis(self.V, self.particles, gradients=True, domain=self.options.particle_domain)
        self.extended_steps += basis.extended
        return basis

    def _move_corners(self, basis: ParticleBasis, corner_velocity: npt.NDArray, dt: float) -> None:
        r"""CPDI2: corners :math:`y_c^+ = y_c + \Delta t\, u_c` with the corners' velocities
        ``corner_velocity`` (n, corners, d), the grid velocity at them,
        :math:`u_c = \sum_i N_i(y_c) v_i^+` (``basis.gather_samples``; with contact each body's
        own field); the particle moves to its domain's centroid and takes its volume (for
        simplices the centroid moves by :math:`\Delta t \sum_i \langle N_i \rangle_p v_i^+` and
        :math:`|\Omega_p| = J_p V_p^0`, since :math:`L_p` is the gradient of the corner
        velocities' linear interpolant)."""
        p = self.particles
        corners = p.fields["corners"] + dt * corner_velocity
        try:
            _, _, volume, centroid = domain_geometry(corners, p.comm)  # collective error
        except ValueError as e:
            self._fail(f"inverted particle domain: {e}")
        p.fields["corners"], p.x, p.volume = corners, centroid, volume

    def _check_finite(self) -> None:
        """Positions, stresses and the kinetic energy density :math:`v_p \\cdot v_p` (hence the
        velocities) finite at every particle, else a :class:`SimulationError` (collective)."""
        p = self.particles
        f = p.fields
        speed2 = np.einsum("nd,nd->n", f["v"], f["v"]) if len(p) else np.zeros(0)
        bad = ~(np.isfinite(p.x).all(1) & np.isfinite(speed2) & np.isfinite(f["sigma"]).all((1, 2)))
        if p.comm.allreduce(int(bad.sum())):
            self._fail(f"non-finite state at particle(s) {self._ids(bad)}")

    # -- diagnostics --------------------------------------------------------------------------
    def grid_stress(self, mass: Literal["lumped", "consistent"] | None = None) -> dolfinx.fem.Function:
        """The Cauchy stress on the grid, a tensor Lagrange Function of ``V``'s degree and variant
        (:func:`fempm.stepping.diagnostics.grid_stress`; the space is made on first use).

        Note:
            Collective.
        """
        if self._stress_space is None:
            self._stress_space = diagnostics.stress_space(self.V)
        return diagnostics.grid_stress(self._stress_space, self.particles, self.options, mass)

    def energies(self) -> dict[str, float]:
        """Kinetic, strain and total energy and linear momentum (:func:`fempm.stepping.diagnostics.energies`).

        Note:
            Collective.
        """
        return diagnostics.energies(self.particles, self.materials, self.t)
