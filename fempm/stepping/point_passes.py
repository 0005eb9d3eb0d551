r"""The compiled particle passes of the point grid (:class:`PointPasses`): P2G and G2P of point
particles on a space of the compiled kernels (:mod:`fempm.kernels.lumped`), the arrays and
bundles they take, and the laws they evaluate. :class:`fempm.stepping.lumped.PointGrid` orders
them into the stages of a step; :class:`fempm.stepping.domain_grid.DomainGrid` and
:class:`fempm.stepping.contact_points.ContactPointGrid` change the passes.
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
from fempm.kernels.grid_update import affine_cutoff_velocity
from fempm.kernels.lumped import NO_STABLE
from fempm.kernels.particle_checks import LINEAR_ELASTIC, NEO_HOOKEAN
from fempm.materials.base import IsotropicElastic
from fempm.materials.linear_elastic import LinearElastic
from fempm.materials.neo_hookean import NeoHookean
from fempm.stepping.grid import Grid
from fempm.stepping.laws import material_groups, stresses_of
from fempm.stepping.loads import external_forces
from fempm.stepping.nodal import kept_nodal_array, sum_ghosts
from fempm.stepping.spaces import compiled_space
from fempm.stepping.state import StepState
from fempm.transfer.centres import NodalCentres
from fempm.transfer.mapping import mass_centres
from fempm.transfer.mass_models import FMPM, Lumped

__all__ = ["PointPasses"]


def _law(mat) -> tuple[int, float, float, float]:
    """(compiled law code, lambda, mu, P-wave modulus or 0) of a material."""

    code = {NeoHookean: NEO_HOOKEAN, LinearElastic: LINEAR_ELASTIC}.get(type(mat), 0)
    lam, mu = mat.lame if code else (0.0, 0.0)
    wave = isinstance(mat, IsotropicElastic) and type(mat).wave_speed is IsotropicElastic.wave_speed
    modulus = sum(mat.lame) + mat.lame[1] if wave else 0.0
    return code, lam, mu, modulus


class PointPasses(Grid):
    """The compiled particle passes of a point grid and what they take (see the module): the
    space's cells and dofs, the laws' bundle, the kept nodal arrays, the affine transfers' state."""

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
        self._cutoff: tuple | None = None  # kept arrays of affine_velocity: (the velocity, the flags)
        self.top = 0.0  # the step's largest nodal mass, over all ranks (set as the step opens)
        self._sums = np.zeros(3 + d)  # the moving pass's sums of the state (state_sums)
        self._summed = False  # whether they are the last step's


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

    def affine_state(self, cutoff: tuple | None = None) -> tuple[Affine, int]:
        """The passes' affine bundle (the particles' ``affine`` and ``affine_spin`` fields, the
        dofs' coordinates and the ``cutoff`` = (the grid velocity G2P takes the affine matrices
        from, a flag per dof where it differs from the updated one) of :meth:`affine_velocity`,
        None: the updated one everywhere) and the transfer's code (0: none; :mod:`fempm.kernels.affine`)."""
        s = self.state
        kind = self.options.velocity_transfer.kind
        if not kind:
            return NO_AFFINE, 0
        C, spin = s.affine()
        v, weak = (np.zeros((0, self.d)), np.zeros(0, np.uint8)) if cutoff is None else cutoff
        return Affine(C, np.zeros((len(C), 0)) if spin is None else spin, s.dof_coordinates(), v, weak), kind

    def affine_velocity(self, v_new: npt.NDArray, v_old: npt.NDArray) -> tuple | None:
        """(The grid velocity G2P takes the affine matrices from under ``affine_cutoff``,
        :func:`fempm.transfer.affine.affine_velocity` of the step's lumped masses, a flag per dof
        below the cutoff, where it differs from ``v_new``), None where it is the updated velocity
        itself (no cutoff, or no node below it)."""
        cut = self.options.affine_share
        if not cut:
            return None
        m = self._nodal[1][:, 0]
        if self._cutoff is None or self._cutoff[0].shape != v_new.shape or len(self._cutoff[1]) != len(m):
            self._cutoff = (np.empty_like(v_new), np.empty(len(m), dtype=np.uint8))
        v, flags = self._cutoff
        if not affine_cutoff_velocity(v_new, v_old, m, cut * self.top, v, flags):
            return None
        return v, flags

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
        local = self.scatter_pass(self.particle_state(velocity), forces, out, cm, cv, cf, times, bound=stable == "bound",
                                  groups=groups, cg=cg, affine=carried, kind=kind)
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

    def scatter_pass(self, state: State, forces: Forces, out, cm: int, cv: int, cf: int, stable: Stable, *,
                     bound: bool = False, groups: Groups = NO_GROUPS, cg: int = -1, affine: Affine = NO_AFFINE,
                     kind: int = 0) -> float:
        """The P2G pass (:func:`fempm.kernels.lumped.kernels_for`) with the particles' basis."""
        p = self.state.particles
        where = Basis(p.cells, p.X, self.K, self.cell_dofs)
        return self.kernels.scatter(where, state, self.laws, forces, out, cm, cv, cf, stable, bound=bound,
                                    groups=groups, cg=cg, affine=affine, kind=kind)

    def gather_pass(self, grid: GridStep, state: State, moves: Moves, outputs: Outputs, *, blend: bool,
                    kinematics: bool, move: bool, average=None) -> tuple:
        """The G2P pass (:func:`fempm.kernels.lumped.kernels_for`) with the particles' basis; a
        blend pass of APIC or TPIC also stores the affine matrices (and re-maps with them with
        the lumped mass); ``average``: F-bar's averaged kinematics (:mod:`fempm.stepping.fbar_grid`)."""
        p = self.state.particles
        carried, kind = self.affine_state(self.affine_velocity(grid.v_new, grid.v_old)) if blend else (NO_AFFINE, 0)
        return self.kernels.g2p_update(Basis(p.cells, p.X, self.K, self.cell_dofs), grid, state, self.laws, moves,
                                       outputs, blend=blend, kinematics=kinematics, move=move, affine=carried,
                                       kind=kind, remap_affine=self.affine_with_momenta, average=average)

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

    def particle_pass(self, v_new, v_old, dt, *, blend: bool, kinematics: bool, move: bool, remap=None, average=None):
        """One particle pass (:func:`fempm.kernels.lumped.kernels_for`; ``average``: with F-bar's
        averaged kinematics); checks J (collective) after a kinematics pass; returns (#non-finite particles, which left their cells and
        are not in an owned neighbour (a moving pass; else an empty mask))."""

        s = self.state
        p = s.particles
        opts = s.options
        external = kinematics and self.any_external
        L = np.empty((len(p) if external else 0, self.d, self.d))
        left = np.empty(len(p) if move else 0, dtype=np.bool_)
        grid = GridStep(v_new, v_old, float(opts.velocity_transfer.blend), float(dt), opts.particle_position)
        moves = Moves(self.x0, p.locator.tol, left, p.locator.vertex_star())
        outputs = Outputs(L, remap if remap is not None else np.zeros((0, self.d)),
                          self._sums if move and self.totals else np.zeros(0))
        counts = self.gather_pass(grid, self.particle_state(), moves, outputs, blend=blend, kinematics=kinematics,
                                  move=move, **({} if average is None else {"average": average}))
        nonfinite_j, inverted, jmin, jmax, nonfinite = counts
        if kinematics:
            nonfinite += self.kinematics_checks((nonfinite_j, inverted, jmin, jmax), L if external else None, dt)
        return nonfinite, left

    def kinematics_checks(self, counts: tuple, L: npt.NDArray | None, dt: float) -> int:
        """After a kinematics pass: its ``counts`` (#non-finite J, #J <= 0, min J, max J) checked
        on every rank (one collective; a failure names the particles), the J range recorded and,
        with the particles' velocity gradients ``L`` (n, d, d), the stress of the laws without a
        compiled kernel; returns the number of those particles whose stress is not finite."""
        s = self.state
        p = s.particles
        f = p.fields
        nonfinite_j, inverted, jmin, jmax = counts
        flags = np.array([nonfinite_j, inverted, -jmin, jmax], dtype=float)
        p.comm.Allreduce(MPI.IN_PLACE, flags, op=MPI.MAX)
        if flags[0]:
            s.fail(f"non-finite state (deformation gradient) at particle(s) {s.particle_ids(~np.isfinite(p.volume))}")
        if flags[1]:
            s.fail(f"inverted deformation J <= 0 at particle(s) {s.particle_ids(p.volume <= 0)}")
        s.record.j_range = (-float(flags[2]), float(flags[3]))
        nonfinite = 0
        if L is not None:  # laws without a compiled kernel
            groups = [(mat, idx) for b, (mat, idx) in enumerate(material_groups(f, s.materials))
                      if self.law[b] == 0 and len(idx)]
            stresses_of(p.comm, groups, f["F"], L, f["sigma"], dt, p.mass / p.volume, f)
            for _, idx in groups:
                nonfinite += int(np.count_nonzero(~np.isfinite(f["sigma"][idx]).all(axis=(1, 2))))
        return nonfinite

    def _state(self) -> tuple:
        """Identities of the particle arrays the passes read and check."""
        p = self.state.particles
        f = p.fields
        return id(p.x), id(f["v"]), id(f["sigma"]), id(f["F"]), id(f["body"])
