r"""The grid of point particles on degree-1 cells, in compiled passes (:class:`PointGrid`).

The stages of :mod:`fempm.stepping.grid` (same equations, options and checks; the numpy
:class:`~fempm.stepping.grid.SingleFieldGrid` is the reference it is tested against to
round-off) for the common case: standard MPM particles, lumped or consistent mass
(:class:`LumpedNodalMass`, :class:`~fempm.stepping.consistent.ConsistentNodalMass`), a P1/Q1
vector space on a mesh of simplices, quadrilaterals or hexahedra with straight edges (affine
or multilinear maps: :mod:`fempm.kernels.shape`) (FMPM(k):
:mod:`fempm.stepping.fmpm_mass`; particle domains: :mod:`fempm.stepping.domain_grid`). Nothing per particle
is stored between the passes; the basis is evaluated on the fly in each pass
(:mod:`fempm.kernels.shape`):

1. P2G: mass, momentum and force in one pass into one nodal array (ghosts summed once), with
   the stable step of the state, :math:`\Delta t = \mathrm{CFL} \min_p h_{c(p)} / (c_p + |v_p|)`;
2. grid update: :math:`v = (mv)/m`, boundary conditions, :math:`v^+ = v + \Delta t f/m`;
3. G2P: FLIP blend, :math:`L_p`, :math:`F_p`, :math:`J_p` and its checks, the stress of the
   compiled laws, the position, the finiteness check and the reference coordinates in the same
   cell in one pass, state updated in place; a particle that left its cell is looked for in
   the owned cells sharing a vertex with it in the same pass;
4. relocation: the DOLFINx tree (and migration) only for the particles not found there.

USF splits 1 (forces after the stress update) and MUSL adds a momentum re-map between the
blend and the kinematics (:mod:`fempm.stepping.schemes`). Laws other than :class:`~fempm.materials.NeoHookean`
and :class:`~fempm.materials.LinearElastic` keep their own ``stress`` (given :math:`L_p`) and
``wave_speed``, called after the pass (:class:`~fempm.materials.VonMises` runs the compiled
kernels of :mod:`fempm.kernels.plasticity` there).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.kernels.grid_update import grid_update
from fempm.kernels.shape import space_of
from fempm.stepping import diagnostics
from fempm.stepping.fmpm_mass import FMPMNodalMass
from fempm.stepping.grid import Grid
from fempm.stepping.lumped_mass import NODAL_MASSES, LumpedNodalMass
from fempm.stepping.nodal import NodalLayout, sum_ghosts
from fempm.stepping.point_passes import PointPasses
from fempm.stepping.spaces import space_refusal
from fempm.stepping.state import StepState
from fempm.transfer.domains import Point
from fempm.transfer.grid_solves import negative_basis_message
from fempm.transfer.mapping import SUPPORT_TOL
from fempm.transfer.mass_models import Consistent

__all__ = ["BOUND_SAFETY", "NODAL_MASSES", "SORT_EVERY", "LumpedNodalMass", "PointGrid"]


#: steps between two sorts of the particles by cell
SORT_EVERY = 100
#: a given dt at most this fraction of the bound of the stable time needs no exact check
#: (the bound's own rounding)
BOUND_SAFETY = 1.0 - 1e-12


class PointGrid(PointPasses):
    """The stages of the explicit step in compiled passes, for point particles on affine
    degree-1 cells (see the module); the grid mass, lumped or consistent, is a
    :class:`LumpedNodalMass` or a :class:`fempm.stepping.consistent.ConsistentNodalMass`."""

    #: the options this grid takes, in messages (:mod:`fempm.stepping.grid_choice`)
    takes = "point particles with lumped, consistent or FMPM mass on a space of the compiled passes"
    #: the velocity transfers its passes take
    transfers = ("flip", "pic", "apic", "tpic", "xpic")
    #: the grid mass of each mass model
    nodal_masses = NODAL_MASSES
    #: the step's averaged basis of particle domains (:class:`~fempm.stepping.domain_grid.DomainGrid`); none here
    samples = None

    @classmethod
    def refusal(cls, state: StepState) -> str | None:
        """Why ``state``'s options, space and mesh do not take this grid (None where they do):
        point particles, lumped, consistent (:mod:`fempm.stepping.consistent`) or FMPM
        (:mod:`fempm.stepping.fmpm_mass`) mass, a space of :func:`~fempm.stepping.spaces.compiled_space`."""
        opts = state.options
        space = space_refusal(state)
        if space is not None:
            return space
        if type(opts.mass_model) not in NODAL_MASSES:
            return f"mass {opts.mass_model.label}: lumped, consistent or FMPM"
        if not isinstance(opts.particle_domain, Point):
            return f"particle domain {opts.particle_domain.name}: point particles"
        if opts.velocity_transfer.name not in cls.transfers:
            return f"transfer {opts.velocity_transfer.name}: {', '.join(cls.transfers)}"
        return None
    def __init__(self, state: StepState):
        super().__init__(state)
        self.since_sort = SORT_EVERY  # steps since the particles were sorted by cell (sort on the first step)
        if space_of(self.cell) == (2, False) and type(self.options.mass_model) is not Consistent:
            raise ValueError(negative_basis_message(self.options.mass_model.label, 2))  # as the numpy step
        #: what a grid mass reads of this grid
        self.layout = layout = NodalLayout(state, self.cell, self.K, self.cell_dofs, self.index_map, self.free,
                                           self.mass_apply, self.samples)
        self.mass = self.nodal_masses[type(self.options.mass_model)](layout)
        transfer = self.options.velocity_transfer
        #: XPIC(m)'s series (none for the consistent mass, whose projection is exact: XPIC(inf))
        self.xpic = (FMPMNodalMass(layout, transfer.order)
                     if transfer.extrapolates and type(self.options.mass_model) is not Consistent else None)
        # every boundary condition a zero component, held by `free`, and a lumped mass: one fused grid pass
        self.fused = self.conditions.zero_components and self.mass.fusable

    # -- the stages ---------------------------------------------------------------------------
    def for_step(self) -> Grid:
        """The checks of a state set from outside the passes and, every :data:`SORT_EVERY`
        steps, the sort of the particles by cell; this grid takes the step."""
        s = self.state
        p = s.particles
        if p.comm.allreduce(self._state() != self._checked, op=MPI.LOR):  # arrays set from outside (any rank)
            s.check_state()  # collective; the passes check their own results
        if self.since_sort >= SORT_EVERY:
            p.sort_by_cell()
            self.since_sort = 0
        self.since_sort += 1
        self._summed = False
        return self

    def open(self, dt: float | None) -> float:
        s = self.state
        opts = self.options
        p = s.particles
        d = self.d
        self.external = self._external(s.t)
        # a given dt is checked against a lower bound of the stable time, and against the time
        # itself only where the bound does not show it stable
        nodal, local = self._scatter(self._nodal, self.external, 0, 1, 1 + d if opts.stages.forces_with_map else -1,
                                     stable="exact" if dt is None else "bound", affine=self.affine_with_momenta)
        self.start = self.affine_momenta() if self.affine_apart else None
        top = np.array([nodal[: self.num_owned, 0].max(initial=0.0), -local])
        p.comm.Allreduce(MPI.IN_PLACE, top, op=MPI.MAX)  # one collective: the largest mass and the stable time
        top, state = float(top[0]), -float(top[1])
        self.top, self.active_min, self.weak_max = top, SUPPORT_TOL * top, opts.mass_cutoff * top
        factor = self.mass.stable_factor(nodal, dt is None, top)
        if self.xpic is not None:
            self.xpic.stable_factor(nodal, dt is None, top)  # (its lumped rows)
        if dt is not None and not dt <= state * BOUND_SAFETY * factor:
            state = self._stable_time()
        self.centroids = self._centroids(nodal)
        self.force, self.cf = nodal, 1 + d
        self.nonfinite, self.left = 0, None
        return opts.cfl * state * factor

    def update(self, dt: float) -> tuple[npt.NDArray, npt.NDArray]:
        if not self.fused:
            return super().update(dt)
        v_old, v_new = np.empty((self.num_dofs, self.d)), np.empty((self.num_dofs, self.d))
        grid_update(self._nodal[1], 1, 1 + self.d, self.free, self.active_min, self.weak_max, float(dt),
                       float(self.options.damping), v_old, v_new)
        return v_old, v_new

    def velocity(self, remapped: bool = False) -> npt.NDArray:
        nodal = self._nodal[1]
        if remapped:
            start = self.affine_momenta() if self.affine_apart else None
            return self.mass.velocity(nodal[:, :1], self._nodal_d[1], 0, self.active_min, None, self.centroids,
                                      start=start)
        mapped = self.options.stages.forces_with_map and self.force is nodal  # forces mapped with momenta (USL, MUSL)
        forces = self.cf if mapped else None
        return self.mass.velocity(nodal[:, :1], nodal, 1, self.active_min, self.state.grid_velocity, self.centroids,
                                  forces, start=self.start)

    def forces(self) -> None:
        self.force, self.cf = self._scatter(self._nodal_d, self.external, -1, -1, 0)[0], 0

    def advance(self, v_old: npt.NDArray, dt: float) -> npt.NDArray:
        return self.mass.advance(self._nodal[1][:, :1], self.force, self.cf, self.active_min, self.weak_max, dt,
                                 v_old, self.centroids)

    def extrapolated(self, v_old: npt.NDArray) -> npt.NDArray:
        r"""XPIC(m)'s :math:`v^*`: the series of FMPM(m) on the step's mapped momenta (the consistent
        mass: ``v_old``, its exact projection), constrained (:mod:`fempm.transfer.transfers`)."""
        if self.xpic is None:
            return v_old
        nodal = self._nodal[1]
        return self.xpic.velocity(nodal[:, :1], nodal, 1, self.active_min, None, self.centroids)

    def to_particles(self, v_new: npt.NDArray, v_old: npt.NDArray, dt: float, *, blend: bool = False,
                     kinematics: bool = False, move: bool = False, remap: bool = False) -> None:
        if blend and self.options.velocity_transfer.extrapolates:  # XPIC(m): a blend pass of its own field
            self.record_reaction(v_new, v_old, dt)
            self._blend(self.extrapolated(v_old) + v_new - v_old, v_old, dt, remap)
            if kinematics or move:
                self.to_particles(v_new, v_new, dt, kinematics=kinematics, move=move)
            return
        if blend:
            self.record_reaction(v_new, v_old, dt)
        if remap:  # the blended particle momenta into the kept nodal array, for velocity(remapped=True)
            self._blend(v_new, v_old, dt, remap)
            return
        nonfinite, left = self.particle_pass(v_new, v_old, dt, blend=blend, kinematics=kinematics, move=move)
        self.nonfinite += nonfinite
        if move:
            self.left = left
            self._summed = self.totals

    def _blend(self, v_new: npt.NDArray, v_old: npt.NDArray, dt: float, remap: bool) -> None:
        """A blend pass alone (with ``remap``: the blended momenta into the kept nodal array, for
        :meth:`velocity` with ``remapped``)."""
        if not remap:
            self.nonfinite += self.particle_pass(v_new, v_old, dt, blend=True, kinematics=False, move=False)[0]
            return
        vec, mom = self._nodal_d
        mom.fill(0.0)
        self.particle_pass(v_new, v_old, dt, blend=True, kinematics=False, move=False, remap=mom)
        sum_ghosts(vec)

    def reaction_fields(self, v_new: npt.NDArray, v_old: npt.NDArray) -> list[tuple]:
        nodal, d = self._nodal[1], self.d
        moving = nodal[:, 0] > self.weak_max
        return [(self.mass.lumped(nodal), nodal[:, 1:1 + d], self.force[:, self.cf:self.cf + d], v_old, v_new, moving)]

    def close(self) -> None:
        if self.state.particles.comm.allreduce(self.nonfinite):
            self.state.check_finite()  # names the particles

    def relocate(self) -> None:
        self.state.relocate_particles(left=self.left)
        self._checked = self._state()

    def nodal(self, v: npt.NDArray) -> npt.NDArray:
        return v[: self.num_dofs]

    def state_sums(self) -> npt.NDArray | None:
        """The moving pass's sums (:func:`fempm.kernels.lumped._g2p_kernel`, ``totals``), with the
        strain energy of the laws without a compiled kernel added from the state."""
        if not self._summed:
            return None
        s = self.state
        sums = self._sums.copy()
        if self.any_external:
            sums[1] += diagnostics.strain_energy(s.particles, s.materials, self.law == 0)
        return sums

    def checkpoint_state(self) -> tuple[dict, dict[str, npt.NDArray]]:
        counters, arrays = self.mass.checkpoint_state()
        return {"since_sort": self.since_sort, **counters}, arrays

    def restore_state(self, counters: dict, arrays: dict[str, npt.NDArray]) -> None:
        if counters.get("since_sort") is not None:
            self.since_sort = int(counters["since_sort"])
        self.mass.restore_state(counters, arrays)
