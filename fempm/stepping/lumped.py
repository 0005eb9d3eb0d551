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

from fempm.kernels import fmpm as kf
from fempm.kernels import lumped as kl
from fempm.kernels.bundles import (
    NO_AFFINE,
    NO_GROUPS,
    Affine,
    Basis,
    Forces,
    GridStep,
    Groups,
    Laws,
    Moves,
    Outputs,
    Stable,
    State,
)
from fempm.kernels.lumped import NO_STABLE
from fempm.kernels.shape import space_of
from fempm.materials.base import IsotropicElastic
from fempm.materials.linear_elastic import LinearElastic
from fempm.materials.neo_hookean import NeoHookean
from fempm.stepping import diagnostics
from fempm.stepping.grid import Grid
from fempm.stepping.laws import material_groups, stresses_of
from fempm.stepping.loads import external_forces
from fempm.stepping.fmpm_mass import FMPMNodalMass
from fempm.stepping.lumped_mass import NODAL_MASSES, LumpedNodalMass
from fempm.stepping.nodal import NodalLayout, kept_nodal_array, sum_ghosts
from fempm.stepping.spaces import compiled_space, space_refusal
from fempm.stepping.state import StepState
from fempm.transfer.centres import NodalCentres
from fempm.transfer.domains import Point
from fempm.transfer.grid_solves import negative_basis_message
from fempm.transfer.mapping import SUPPORT_TOL, mass_centres
from fempm.transfer.mass_models import FMPM, Consistent, Lumped
from fempm.transfer.transfers import AFFINE_FIELD, SPIN_FIELD

__all__ = ["BOUND_SAFETY", "NODAL_MASSES", "SORT_EVERY", "LumpedNodalMass", "PointGrid"]


#: steps between two sorts of the particles by cell
SORT_EVERY = 100
#: a given dt at most this fraction of the bound of the stable time needs no exact check
#: (the bound's own rounding)
BOUND_SAFETY = 1.0 - 1e-12


def _law(mat) -> tuple[int, float, float, float]:
    """(compiled law code, lambda, mu, P-wave modulus or 0) of a material."""

    code = {NeoHookean: kl.NEO_HOOKEAN, LinearElastic: kl.LINEAR_ELASTIC}.get(type(mat), 0)
    lam, mu = mat.lame if code else (0.0, 0.0)
    wave = isinstance(mat, IsotropicElastic) and type(mat).wave_speed is IsotropicElastic.wave_speed
    modulus = sum(mat.lame) + mat.lame[1] if wave else 0.0
    return code, lam, mu, modulus


class PointGrid(Grid):
    """The stages of the explicit step in compiled passes, for point particles on affine
    degree-1 cells (see the module); the grid mass, lumped or consistent, is a
    :class:`LumpedNodalMass` or a :class:`fempm.stepping.consistent.ConsistentNodalMass`."""

    #: the options this grid takes, in messages (:mod:`fempm.stepping.grid_choice`)
    takes = "point particles with lumped, consistent or FMPM mass on a space of the compiled passes"
    #: the velocity transfers its passes take
    transfers = ("flip", "pic", "apic", "tpic", "xpic")

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
        p, V = state.particles, state.V
        geo = p.locator.geometry
        self.cell = compiled_space(state)  # the kernels' cell type
        self.x0, self.K = geo.kernel_geometry
        self.kernels = kl.kernels_for(self.cell)
        self.cell_dofs = np.ascontiguousarray(V.dofmap.list, dtype=np.int32)
        self.index_map = V.dofmap.index_map
        self.num_owned = self.index_map.size_local
        self.num_dofs = self.num_owned + self.index_map.num_ghosts
        d = self.d = p.gdim
        self.conditions = state.conditions
        self.free = self.conditions.free(d)  # (dof, component) solved for
        laws = [_law(m) for m in state.materials]
        self.law = np.array([a[0] for a in laws], dtype=np.int64)
        self.lam = np.array([a[1] for a in laws])
        self.mu = np.array([a[2] for a in laws])
        self.modulus = np.array([a[3] for a in laws])
        self.laws = Laws(self.law, self.lam, self.mu, self.modulus)  # the passes' bundle
        self.no_forces = Forces(np.zeros(d), np.zeros((0, d)))  # the passes that map no force
        self.all_modulus = bool(np.all(self.modulus > 0))
        self.any_external = bool(np.any(self.law == 0))
        self.since_sort = SORT_EVERY  # steps since the particles were sorted by cell (sort on the first step)
        self._nodal = self.nodal_array(1 + 2 * d)  # [m | m v | f]
        self._nodal_d = self.nodal_array(d)  # USF's forces, MUSL's re-mapped momenta
        # walls that check contact by position: the first mass moments sum_p M_p N_ip x_p
        self._moments = self.nodal_array(d) if self.conditions.needs_positions else None
        self._checked: tuple | None = None  # identities of the state arrays checked finite
        # APIC/TPIC: the lumped mass maps the affine part with the momenta, FMPM apart (its
        # lumped first solve alone, into a kept array), the consistent mass not at all
        self.affine_with_momenta = state.options.velocity_transfer.affine and type(state.options.mass_model) is Lumped
        self.affine_apart = state.options.velocity_transfer.affine and type(state.options.mass_model) is FMPM
        self._start = self.nodal_array(d) if self.affine_apart else None
        self.start: npt.NDArray | None = None
        self._sums = np.zeros(3 + d)  # the moving pass's sums of the state (state_sums)
        self._summed = False  # whether they are the last step's
        if space_of(self.cell) == (2, False) and type(self.options.mass_model) is not Consistent:
            raise ValueError(negative_basis_message(self.options.mass_model.label, 2))  # as the numpy step
        layout = NodalLayout(state, self.cell, self.K, self.cell_dofs, self.index_map, self.free, self.mass_apply)
        self.mass = NODAL_MASSES[type(self.options.mass_model)](layout)
        transfer = self.options.velocity_transfer
        #: XPIC(m)'s series (none for the consistent mass, whose projection is exact: XPIC(inf))
        self.xpic = (FMPMNodalMass(layout, transfer.order)
                     if transfer.extrapolates and type(self.options.mass_model) is not Consistent else None)
        # every boundary condition a zero component, held by `free`, and a lumped mass: one fused grid pass
        self.fused = self.conditions.zero_components and self.mass.fusable

    # -- pieces -------------------------------------------------------------------------------
    def nodal_array(self, k: int):
        """A nodal (owned + ghost dofs, k) array kept for the run: (vector or None, array)."""
        return kept_nodal_array(self.index_map, k)

    def _wave_speeds(self) -> npt.NDArray:
        """Wave speeds of the particles whose law has no P-wave modulus (empty if none has)."""
        s = self.state
        p = s.particles
        if self.all_modulus:
            return np.zeros(0)
        c = np.zeros(len(p))
        rho = p.mass / p.volume
        for b, (mat, idx) in enumerate(material_groups(p.fields, s.materials)):
            if self.modulus[b] <= 0:
                c[idx] = mat.wave_speed(p.fields["F"][idx], rho[idx])
        return c

    def _external(self, t: float) -> Forces:
        """The external forces of the P2G pass: a constant body force g (d,), or per-particle
        forces (n or 0, d)."""
        s = self.state
        loads = s.loads
        s.count_terms()
        if not loads.per_particle:
            g = np.zeros(self.d) if loads.body_force is None else np.asarray(loads.body_force, dtype=np.float64)
            if g.shape != (self.d,):
                raise ValueError(f"the body force has shape {g.shape}, expected ({self.d},)")
            return Forces(g, np.zeros((0, self.d)))
        return Forces(np.zeros(self.d), np.ascontiguousarray(external_forces(loads, s.particles, t)))

    def particle_state(self, velocity: npt.NDArray | None = None) -> State:
        """The particle state the passes read and update (``velocity``: the vectors a P2G pass
        maps in the place of the particles' velocities)."""
        p = self.state.particles
        f = p.fields
        return State(p.x, f["v"] if velocity is None else velocity, f["F"], f["volume0"], p.volume, f["sigma"],
                     f["body"], p.mass)

    def affine_state(self) -> tuple[Affine, int]:
        """The passes' affine bundle (the particles' ``affine`` and ``affine_spin`` fields and the
        dofs' coordinates) and the transfer's code (0: none; :mod:`fempm.kernels.affine`)."""
        s = self.state
        kind = self.options.velocity_transfer.kind
        if not kind:
            return NO_AFFINE, 0
        f = s.particles.fields
        s.affine()
        spin = f.get(SPIN_FIELD)
        if spin is None:
            spin = np.zeros((len(s.particles), 0))
        return Affine(f[AFFINE_FIELD], spin, s.dof_coordinates()), kind

    def _scatter(self, nodal, forces: Forces, cm: int, cv: int, cf: int, stable: str = "", velocity=None,
                 groups: Groups = NO_GROUPS, cg: int = -1, affine: bool = False):
        """P2G of the chosen columns into the kept ``nodal`` (vector, array), summed over
        ranks; with ``stable`` ("exact" or "bound") also this rank's stable time of the state
        or a lower bound of it (:func:`fempm.kernels.lumped._scatter_kernel`; else inf);
        ``velocity``: the vectors the momentum column maps in the place of the particles'
        velocities; ``groups`` and ``cg``: multi-field contact's groups and mass-gradient column;
        ``affine``: the momenta with the particles' affine part (APIC, TPIC with the lumped mass)."""
        s = self.state
        vec, out = nodal
        out.fill(0.0)
        times = Stable(s.h_cell, self._wave_speeds()) if stable else NO_STABLE
        carried, kind = self.affine_state() if affine else (NO_AFFINE, 0)
        local = self.scatter_pass(self.particle_state(velocity), forces, out, cm, cv, cf, times, stable == "bound",
                                  groups, cg, carried, kind)
        sum_ghosts(vec)
        return out, local

    def affine_momenta(self) -> npt.NDArray:
        r"""The affine part of P2G alone, :math:`\sum_p M_p N_{ip} C_p (x_i - x_p)`, into the kept
        array, summed over ranks (FMPM's lumped first solve takes it: :mod:`fempm.transfer.transfers`)."""
        p = self.state.particles
        return self._scatter(self._start, self.no_forces, -1, 0, -1, velocity=np.zeros((len(p), self.d)),
                             affine=True)[0]

    def mass_apply(self, y: npt.NDArray, lump: npt.NDArray, out: npt.NDArray) -> None:
        """``out`` += FMPM's :math:`M_C y` on this rank's particles (ghost entries partial sums;
        :func:`fempm.kernels.fmpm.mass_apply`)."""
        p = self.state.particles
        kf.mass_apply(self.cell)(p.cells, p.X, self.K, self.cell_dofs, p.mass, y, lump, out)

    def scatter_pass(self, state: State, forces: Forces, out, cm: int, cv: int, cf: int, stable: Stable,
                     bound: bool = False, groups: Groups = NO_GROUPS, cg: int = -1, affine: Affine = NO_AFFINE,
                     kind: int = 0) -> float:
        """The P2G pass (:func:`fempm.kernels.lumped.kernels_for`) with the particles' basis."""
        p = self.state.particles
        where = Basis(p.cells, p.X, self.K, self.cell_dofs)
        return self.kernels.scatter(where, state, self.laws, forces, out, cm, cv, cf, stable, bound, groups, cg,
                                    affine, kind)

    def gather_pass(self, grid: GridStep, state: State, moves: Moves, outputs: Outputs, *, blend: bool,
                    kinematics: bool, move: bool) -> tuple:
        """The G2P pass (:func:`fempm.kernels.lumped.kernels_for`) with the particles' basis; a
        blend pass of APIC or TPIC also stores the affine matrices (and re-maps with them with
        the lumped mass)."""
        p = self.state.particles
        affine, kind = self.affine_state() if blend else (NO_AFFINE, 0)
        return self.kernels.g2p_update(Basis(p.cells, p.X, self.K, self.cell_dofs), grid, state, self.laws, moves,
                                       outputs, blend=blend, kinematics=kinematics, move=move, affine=affine,
                                       kind=kind, remap_affine=self.affine_with_momenta)

    def _centroids(self, nodal) -> NodalCentres | None:
        r"""The nodal centres of mass :math:`\sum_p M_p N_{ip} x_p / m_i` (one more particle
        pass) and masses when a wall checks contact by position, else None."""
        if self._moments is None:
            return None
        return NodalCentres(mass_centres(nodal[:, 0], self.mass_moments()), nodal[:, 0])

    def mass_moments(self, groups: Groups = NO_GROUPS) -> npt.NDArray:
        r"""The first mass moments :math:`\sum_p M_p N_{ip} x_p` into the kept ``_moments``
        array, summed over ranks (``groups``: as for :meth:`_scatter`)."""
        p = self.state.particles
        return self._scatter(self._moments, self.no_forces, -1, 0, -1, velocity=p.x, groups=groups)[0]

    def _stable_time(self) -> float:
        r"""The stable time of the state, :math:`\min_p h_{c(p)} / (c_p + |v_p|)` over all ranks."""
        s = self.state
        p = s.particles
        local = self.scatter_pass(self.particle_state(), self.no_forces, np.zeros((0, 0)), -1, -1, -1,
                                  Stable(s.h_cell, self._wave_speeds()))
        return -p.comm.allreduce(-local, op=MPI.MAX)

    def _g2p(self, v_new, v_old, dt, *, blend: bool, kinematics: bool, move: bool, remap=None):
        """One particle pass (:func:`fempm.kernels.lumped.kernels_for`); checks J (collective)
        after a kinematics pass; returns (#non-finite particles, which left their cells and
        are not in an owned neighbour (a moving pass; else an empty mask))."""

        s = self.state
        p = s.particles
        f = p.fields
        opts = s.options
        external = kinematics and self.any_external
        L = np.empty((len(p) if external else 0, self.d, self.d))
        left = np.empty(len(p) if move else 0, dtype=np.bool_)
        grid = GridStep(v_new, v_old, float(opts.velocity_transfer.blend), float(dt), opts.particle_position)
        moves = Moves(self.x0, p.locator.tol, left, p.locator.vertex_star())
        outputs = Outputs(L, remap if remap is not None else np.zeros((0, self.d)),
                          self._sums if move and self.totals else np.zeros(0))
        counts = self.gather_pass(grid, self.particle_state(), moves, outputs, blend=blend, kinematics=kinematics,
                                  move=move)
        nonfinite_j, inverted, jmin, jmax, nonfinite = counts
        if kinematics:
            flags = np.array([nonfinite_j, inverted, -jmin, jmax], dtype=float)
            p.comm.Allreduce(MPI.IN_PLACE, flags, op=MPI.MAX)
            if flags[0]:
                s.fail(f"non-finite state (deformation gradient) at particle(s) {s.particle_ids(~np.isfinite(p.volume))}")
            if flags[1]:
                s.fail(f"inverted deformation J <= 0 at particle(s) {s.particle_ids(p.volume <= 0)}")
            s.record.j_range = (-float(flags[2]), float(flags[3]))
            if external:  # laws without a compiled kernel
                groups = [(mat, idx) for b, (mat, idx) in enumerate(material_groups(f, s.materials))
                          if self.law[b] == 0 and len(idx)]
                stresses_of(p.comm, groups, f["F"], L, f["sigma"], dt, p.mass / p.volume, f)
                for _, idx in groups:
                    nonfinite += int(np.count_nonzero(~np.isfinite(f["sigma"][idx]).all(axis=(1, 2))))
        return nonfinite, left

    def _state(self) -> tuple:
        """Identities of the particle arrays the passes read and check."""
        p = self.state.particles
        f = p.fields
        return id(p.x), id(f["v"]), id(f["sigma"]), id(f["F"]), id(f["body"])

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
        kl.grid_update(self._nodal[1], 1, 1 + self.d, self.free, self.active_min, self.weak_max, float(dt),
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
        nonfinite, left = self._g2p(v_new, v_old, dt, blend=blend, kinematics=kinematics, move=move)
        self.nonfinite += nonfinite
        if move:
            self.left = left
            self._summed = self.totals

    def _blend(self, v_new: npt.NDArray, v_old: npt.NDArray, dt: float, remap: bool) -> None:
        """A blend pass alone (with ``remap``: the blended momenta into the kept nodal array, for
        :meth:`velocity` with ``remapped``)."""
        if not remap:
            self.nonfinite += self._g2p(v_new, v_old, dt, blend=True, kinematics=False, move=False)[0]
            return
        vec, mom = self._nodal_d
        mom.fill(0.0)
        self._g2p(v_new, v_old, dt, blend=True, kinematics=False, move=False, remap=mom)
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
