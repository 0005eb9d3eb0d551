r"""The grid of an explicit step: the stages a :class:`~fempm.stepping.schemes.Scheme` orders.

A step (:meth:`fempm.stepping.ExplicitSolver.step`) opens the grid (the P2G of mass and
momentum, and of the forces when the scheme maps them with them, and the stable time step),
chooses the time step, runs the scheme's stages and closes the grid:

.. math::
    m_i v_i = \sum_p M_p v_p N_{ip}, \qquad
    f_i = -\sum_p V_p \sigma_p \nabla N_{ip} + \sum_p N_{ip} f^{ext}_p, \qquad
    v_i^{+} = v_i + \Delta t\, f_i / m_i,

then G2P: :math:`v_p^{+} = \alpha (v_p + \sum_i N_{ip}(v_i^{+} - v_i)) + (1-\alpha) \sum_i N_{ip} v_i^{+}`,
:math:`L_p = \sum_i v_i^{+} \otimes \nabla N_{ip}`, :math:`F_p^{+} = (I + \Delta t L_p) F_p`,
:math:`V_p = J_p V_p^0`, the stress of the particle's law, :math:`x_p^{+} = x_p + \Delta t \sum_i N_{ip} v_i^{+}`
(with the lumped mass :math:`m_i = \sum_p M_p N_{ip}`; the consistent mass and FMPM solve
instead, :mod:`fempm.transfer.mass_models`).

Grids: :class:`SingleFieldGrid` (one velocity field; numpy, every particle domain, mass model
and space: the reference of the compiled passes), :class:`fempm.stepping.contact.ContactGrid`
(a field per body, corrected where bodies meet) and :class:`fempm.stepping.lumped.PointGrid`
(point particles on degree-1 cells in compiled passes).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm import kernels
from fempm.kernels.reactions import reaction_sum
from fempm.stepping.loads import external_forces
from fempm.stepping.particle_stages import ParticleStages
from fempm.stepping.reactions import damping_impulse
from fempm.stepping.state import StepState
from fempm.transfer import affine, g2p
from fempm.transfer.basis import ParticleBasis
from fempm.transfer.mapping import nodal_centroids, p2g, p2g_gradients, sum_over_ranks
from fempm.transfer.mass_models import FMPM, MASS_RATIO_ITERATIONS, MassModel
from fempm.transfer.transfers import AFFINE_FIELD, SPIN_FIELD
from fempm.transfer.projection import Projector

__all__ = ["BasisGrid", "Grid", "SingleFieldGrid"]


class Grid:
    """The stages of an explicit step on the background grid of ``state``.

    Velocities are (owned + ghost dofs, d) arrays. A grid reads the solver's particles,
    options, loads and conditions, and reports to its :class:`~fempm.stepping.state.StepRecord`;
    the solver alone advances its time and step count.
    """

    #: the options this grid takes, in messages (:mod:`fempm.stepping.grid_choice`)
    takes = "every option of its kind"

    @classmethod
    def refusal(cls, state: StepState) -> str | None:
        """Why ``state``'s options, space and mesh do not take this grid (None where they do;
        the numpy grids take every option of their kind)."""
        return None

    def __init__(self, state: StepState):
        self.state = state
        self.options = state.options
        #: whether this step's passes also sum the new state's energies (:meth:`state_sums`)
        self.totals = False
        self._reaction_rows: npt.NDArray | None = None

    def for_step(self) -> Grid:
        """The grid that takes the next step: this one (the default), or one this grid hands the
        step to where it cannot take it itself. Collective."""
        return self

    def open(self, dt: float | None) -> float:
        """P2G of mass and momentum (and of the forces when the scheme maps them then); returns
        the stable time step of the state (the CFL number times the stable time, times the
        mass model's factor). ``dt``: the step the caller gives, None for the stable one
        (a grid may then check a cheaper bound first). Collective."""
        raise NotImplementedError

    def velocity(self, remapped: bool = False) -> npt.NDArray:
        """The grid velocity of the mapped momenta (``remapped``: of the particles' updated
        momenta, mapped again), constrained. Collective."""
        raise NotImplementedError

    def forces(self) -> None:
        """P2G of the forces, when the scheme maps them after the stress update. Collective."""
        raise NotImplementedError

    def advance(self, v_old: npt.NDArray, dt: float) -> npt.NDArray:
        r""":math:`v^+ = v + \Delta t\, a` from the mapped forces, constrained. Collective."""
        raise NotImplementedError

    def update(self, dt: float) -> tuple[npt.NDArray, npt.NDArray]:
        """(v, v^+): :meth:`velocity` then :meth:`advance` (a grid may fuse them)."""
        v_old = self.velocity()
        return v_old, self.advance(v_old, dt)

    def to_particles(self, v_new: npt.NDArray, v_old: npt.NDArray, dt: float, *, blend: bool = False,
                     kinematics: bool = False, move: bool = False, remap: bool = False) -> None:
        """G2P: ``blend`` the particle velocities (PIC/FLIP of ``v_new`` and ``v_old``), update
        their ``kinematics`` (:math:`L_p`, F, J and its checks, the stress) with ``v_new``,
        ``move`` them with ``v_new`` (or their own velocity), ``remap`` their momenta for
        :meth:`velocity` with ``remapped``. Collective."""
        raise NotImplementedError

    def close(self) -> None:
        """The checks after the particle update (finite state). Collective."""
        raise NotImplementedError

    def reaction_fields(self, v_new: npt.NDArray, v_old: npt.NDArray) -> list[tuple]:
        """Per velocity field the grid takes the conditions on: (lumped masses (dofs,), mapped
        momenta, forces, ``v_old``, ``v_new`` (dofs, d), where the update applied accelerations
        (dofs,) bool) of the step's update (:func:`fempm.stepping.reactions.nodal_reaction`)."""
        raise NotImplementedError

    def record_reaction(self, v_new: npt.NDArray, v_old: npt.NDArray, dt: float) -> None:
        """The momentum the grid conditions took in the step whose update led from ``v_old``
        to ``v_new``, and the impulse of the damping (:mod:`fempm.stepping.reactions`), on this
        rank, into the step record's ``reaction`` and ``damping_impulse`` (nothing without
        conditions on given nodes, or without damping). Called by the blend."""
        s, opts = self.state, self.options
        held = s.conditions.held_dofs
        damping = float(opts.damping)
        if held is None and damping == 0.0:
            return
        num_owned = s.V.dofmap.index_map.size_local
        fields = self.reaction_fields(v_new, v_old)
        if damping > 0.0:
            s.record.damping_impulse = sum(damping_impulse(m, vo, moving, dt, damping, num_owned)
                                           for m, _, _, vo, _, moving in fields)
        if held is None:
            return
        if self._reaction_rows is None:
            coupled = opts.mass_model.couples_dofs  # the free rows balance only together
            self._reaction_rows = np.arange(num_owned) if coupled else held[held < num_owned]
        rows = self._reaction_rows
        total, one = np.zeros(s.particles.gdim), np.zeros(s.particles.gdim)
        flip = float(opts.velocity_transfer.blend)
        for field in fields:
            reaction_sum(field, float(dt), flip, damping, rows, one)  # (numpy reference: nodal_reaction)
            total += one
        if len(s.collisions):  # theirs, counted as the colliders' impulses
            total -= s.collisions.nodal_impulse[rows].sum(axis=0)
        s.record.reaction = total

    def relocate(self) -> None:
        """Locate the moved particles (migration between ranks). Collective."""
        raise NotImplementedError

    def state_sums(self) -> npt.NDArray | None:
        r"""This rank's sums over its particles of the state the last step left,
        :math:`[\sum_p \tfrac12 M_p |v_p|^2,\ \sum_p V^0_p W_p,\ \sum_p M_p |v_p|,\ \sum_p M_p v_p]`
        (3 + d), where the step's particle passes accumulated them, else None (the default)."""
        return None

    def checkpoint_state(self) -> tuple[dict, dict[str, npt.NDArray]]:
        """(counters, arrays) a resumed run needs to repeat the next steps bit for bit."""
        return {}, {}

    def restore_state(self, counters: dict, arrays: dict[str, npt.NDArray]) -> None:
        """Restore :meth:`checkpoint_state` (arrays from a run on another number of ranks: {})."""


class BasisGrid(Grid):
    """The numpy stages on a :class:`~fempm.transfer.basis.ParticleBasis` (every particle domain,
    mass model and space): the reference of the compiled passes."""

    def __init__(self, state: StepState):
        super().__init__(state)
        #: the particles' side of the step: basis, kinematics, motion, checks, relocation
        self.particle_stages = ParticleStages(state)
        #: the step's particle basis (set when the grid opens a step)
        self.basis: ParticleBasis | None = None

    def open_basis(self) -> ParticleBasis:
        """:meth:`ParticleStages.open_basis`."""
        return self.particle_stages.open_basis()

    def update_kinematics(self, L: npt.NDArray, dt: float, averaged: bool = True) -> None:
        """:meth:`ParticleStages.update_kinematics` (F-bar over the step's basis)."""
        self.particle_stages.update_kinematics(L, dt, averaged, self.basis)

    def move(self, at_grid: npt.NDArray, corner_velocity, dt: float) -> None:
        """:meth:`ParticleStages.move`."""
        self.particle_stages.move(at_grid, corner_velocity, dt)

    def close(self) -> None:
        self.particle_stages.close()

    def relocate(self) -> None:
        self.particle_stages.relocate()

    def mass_operator(self, basis: ParticleBasis, weights: npt.NDArray | None = None,
                      lump_dofs: npt.NDArray[np.bool_] | None = None, mass: MassModel | None = None) -> Projector:
        """The step's mass with its constraints on ``basis``; ``weights``: per-particle masses in
        place of the particles' (one body's mass); ``lump_dofs``: further dofs (owned + ghost)
        whose rows are lumped, besides the frictional walls'; ``mass``: another mass model than
        the options' (XPIC's series)."""
        s, opts = self.state, self.options
        cond = s.conditions
        lumped = cond.friction_dofs
        if lump_dofs is not None:
            lumped = lump_dofs if lumped is None else lumped | lump_dofs[: len(lumped)]
        return Projector(s.V, s.particles, mass=opts.mass_model if mass is None else mass, basis=basis,
                         petsc_options_prefix=opts.petsc_options_prefix, exclude=cond.fixed_dofs,
                         exclude_components=cond.slip_components, lump_below=opts.lump_below, weights=weights,
                         lump_dofs=lumped)

    def stable_with(self, mass_ops) -> float:
        """The CFL stable step of the state with these mass operators (the smallest factor of the
        mass model over them; the lumped step with ``lumped_forces``)."""
        s, opts = self.state, self.options
        stable = s.stable_dt()
        if opts.lumped_forces:
            return stable

        def ratio() -> float:
            s.record.mass_ratio = min((op.mass_ratio_min(MASS_RATIO_ITERATIONS) for op in mass_ops), default=1.0)
            return s.record.mass_ratio

        return stable * opts.mass_model.stable_factor(ratio)

    def accelerations(self, mass_op: Projector, f_grid: npt.NDArray) -> npt.NDArray:
        """Nodal accelerations from the forces: the mass solve, or with ``lumped_forces`` the
        lumped division on the operator's active dofs."""
        if self.options.lumped_forces and self.options.mass_model.couples_dofs:
            m = mass_op.lumped_masses()
            return np.where(mass_op.active[:, None], f_grid / np.where(m > 0, m, 1.0)[:, None], 0.0)
        return mass_op.solve(f_grid)

    def external(self) -> npt.NDArray:
        """The external forces on the particles now (:func:`fempm.stepping.loads.external_forces`)."""
        s = self.state
        return external_forces(s.loads, s.particles, s.t)

    def internal_and_external(self, basis: ParticleBasis, fext: npt.NDArray,
                              weights: npt.NDArray | None = None) -> npt.NDArray:
        r"""Nodal forces :math:`f_i = \sum_p (-V_p \sigma_p \nabla N_{ip} + N_{ip} f^{ext}_p)`
        with the particles' external forces ``fext`` (:meth:`external`), summed over ranks
        (``weights``: a 0/1 factor per particle, one body's forces); point particles in one
        compiled scatter (:mod:`fempm.kernels`)."""
        s = self.state
        p = s.particles
        volume = p.volume if weights is None else p.volume * weights
        if weights is not None:
            fext = fext * weights[:, None]
        sigma = p.fields["sigma"]
        if self.options.volumetric_average is not None:  # F-bar: the patch-averaged pressure
            sigma = self.options.volumetric_average.force_stress(basis, p.volume, p.fields["body"], len(s.materials),
                                                                 sigma)
        if weights is None and basis.cells is not None and not basis.extended:
            local = kernels.nodal_forces(basis.dofs, basis.values, basis.gradients, p.volume, sigma, fext,
                                         basis.num_dofs_local)
            return sum_over_ranks(basis.index_map, local)
        f = p2g_gradients(basis, -volume[:, None, None] * sigma)
        if s.loads.any:
            f += p2g(basis, fext)
        return f

class SingleFieldGrid(BasisGrid):
    """One velocity field for every particle, numpy stages (see :class:`BasisGrid`)."""

    def open(self, dt: float | None) -> float:
        s, opts = self.state, self.options
        p = s.particles
        self.use_basis(self.open_basis())
        stable = self.stable_with([self.mass_op])
        support = self.mass_op.support_masses()
        self.weak = support <= opts.mass_cutoff * p.comm.allreduce(float(support.max(initial=0.0)), op=MPI.MAX)
        s.count_terms()
        self.f_grid = None
        return stable

    def use_basis(self, basis: ParticleBasis) -> None:
        """Map with ``basis``: its nodal centres of mass where a condition needs them, and the
        step's mass on it (collective)."""
        p = self.state.particles
        self.basis = basis
        self.centroids = nodal_centroids(basis, p.mass, p.x) if self.state.conditions.needs_positions else None
        self.mass_op = self.mass_operator(basis)

    def map_velocity(self, guess: npt.NDArray | None) -> npt.NDArray:
        """Grid velocity from the particle momenta (P2G + mass solve), constrained; with APIC
        or TPIC the affine part of the momenta in the lumped first solve
        (:mod:`fempm.transfer.transfers`)."""
        s = self.state
        p = s.particles
        self.momentum = p2g(self.basis, p.mass[:, None] * p.fields["v"])
        self.pic_momentum = self.momentum
        carried = s.affine()
        start = None
        if carried is not None and not self.options.mass_model.matrix:  # the exact projection leaves it out
            start = affine.affine_momentum(self.options.velocity_transfer.kind, *carried, self.basis,
                                           s.dof_coordinates(), p.x, p.mass)
            self.momentum = self.momentum + start  # (the lumped rows' momenta, for the reactions)
        v = self.mass_op.solve(self.pic_momentum, guess=guess, start=start)
        s.conditions.apply(v, self.centroids)
        return self.basis.update_ghosts(v)  # extra ghosts (remote domain samples) take their owners' values

    def extrapolated(self, v_old: npt.NDArray) -> npt.NDArray:
        r"""XPIC(m)'s :math:`v^*`: the series of FMPM(m) on the mapped momenta from the lumped
        solve, constrained (with the consistent mass the exact projection ``v_old`` itself;
        :mod:`fempm.transfer.transfers`)."""
        opts = self.options
        if opts.mass_model.matrix:
            return v_old
        op = self.mass_operator(self.basis, mass=FMPM(opts.velocity_transfer.order))
        v = op.solve(self.pic_momentum)
        self.state.conditions.apply(v, self.centroids)
        return self.basis.update_ghosts(v)

    def velocity(self, remapped: bool = False) -> npt.NDArray:
        return self.map_velocity(None if remapped else self.state.grid_velocity)

    def initial_velocity(self) -> npt.NDArray:
        """The grid velocity of the present state (P2G of the momenta, the mass solve and the
        conditions) on the space's dofs, nothing advanced or recorded. Collective."""
        s = self.state
        self.use_basis(ParticleBasis(s.V, s.particles, gradients=False, domain=self.options.particle_domain))
        return self.map_velocity(None)[: self.basis.num_dofs_space]

    def forces(self) -> None:
        self.f_grid = self.internal_and_external(self.basis, self.external())

    def advance(self, v_old: npt.NDArray, dt: float) -> npt.NDArray:
        opts = self.options
        if self.f_grid is None:
            self.forces()
        a = self.accelerations(self.mass_op, self.f_grid)
        if opts.damping > 0.0:
            a -= opts.damping * v_old[: len(a)]
        a[self.weak] = 0.0  # nodes with a tiny share of mass keep their mapped velocity, no force update
        v_new = v_old + dt * a
        self.state.conditions.apply(v_new, self.centroids, dt)
        return self.basis.update_ghosts(v_new)

    def to_particles(self, v_new: npt.NDArray, v_old: npt.NDArray, dt: float, *, blend: bool = False,
                     kinematics: bool = False, move: bool = False, remap: bool = False) -> None:
        s = self.state
        p = s.particles
        fld = p.fields
        basis = self.basis
        transfer = self.options.velocity_transfer
        if blend and transfer.extrapolates:  # XPIC(m): the particles take the extrapolated field
            self.record_reaction(v_new, v_old, dt)
            fld["v"] = basis.gather(self.extrapolated(v_old) + v_new - v_old)
            blend = False
        if blend:
            self.record_reaction(v_new, v_old, dt)
            fld["v"], at_grid, L = g2p.blend(basis, v_new, v_old, fld["v"], transfer.blend)
        elif kinematics or move:
            at_grid, L = g2p.velocity_and_gradient(basis, v_new)
        if transfer.affine and blend:  # the affine state of the updated grid velocity
            v_affine, L_affine = v_new, L
            if self.options.affine_share:  # weak nodes' accelerations in proportion to their mass
                m = self.mass_op.lumped_masses()
                weak = self.options.affine_share * p.comm.allreduce(float(m.max(initial=0.0)), op=MPI.MAX)
                v_affine = affine.affine_velocity(v_new, v_old, m, weak)
                L_affine = g2p.velocity_and_gradient(basis, v_affine)[1]
            C, spin = affine.grid_affine(transfer.kind, basis, v_affine, s.dof_coordinates(), p.x, L_affine,
                                         v_spin=None if v_affine is v_new else v_new)
            fld[AFFINE_FIELD] = C
            if spin is not None and spin.shape[1]:
                fld[SPIN_FIELD] = spin
        if kinematics:
            self.update_kinematics(L, dt)
        if move:
            self.move(at_grid, lambda: basis.gather_samples(v_new), dt)

    def reaction_fields(self, v_new: npt.NDArray, v_old: npt.NDArray) -> list[tuple]:
        return [(self.mass_op.lumped_masses(), self.momentum, self.f_grid, v_old, v_new, ~self.weak)]

    def nodal(self, v: npt.NDArray) -> npt.NDArray:
        """The grid velocity kept after the step (the space's dofs)."""
        return v[: self.basis.num_dofs_space]
