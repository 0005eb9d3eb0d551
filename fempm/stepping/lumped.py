r"""The lumped-mass step for point particles on affine degree-1 cells, in compiled passes.

This is :meth:`fempm.stepping.ExplicitSolver.step` (same equations, options and checks; that
generic step is the reference it is tested against to round-off) for the common case: standard
MPM particles, lumped mass, a P1/Q1 vector space on a mesh of simplices, parallelograms or
parallelepipeds. Nothing per particle is stored between the passes; the basis is evaluated on
the fly in each pass (:mod:`fempm.kernels.shape`):

1. P2G: mass, momentum and force in one pass into one nodal array (ghosts summed once), with
   the stable step of the state, :math:`\Delta t = \mathrm{CFL} \min_p h_{c(p)} / (c_p + |v_p|)`;
2. grid update: :math:`v = (mv)/m`, boundary conditions, :math:`v^+ = v + \Delta t f/m`;
3. G2P: FLIP blend, :math:`L_p`, :math:`F_p`, :math:`J_p` and its checks, the stress of the
   compiled laws, the position, the finiteness check and the reference coordinates in the same
   cell in one pass, state updated in place; a particle that left its cell is looked for in
   the owned cells sharing a vertex with it in the same pass;
4. relocation: the DOLFINx tree (and migration) only for the particles not found there.

USF splits 1 (forces after the stress update) and MUSL adds a momentum re-map between the
blend and the kinematics, as in the generic step. Laws other than :class:`~fempm.materials.NeoHookean`
and :class:`~fempm.materials.LinearElastic` keep their own ``stress`` (given :math:`L_p`) and
``wave_speed``, called after the pass (:class:`~fempm.materials.VonMises` runs the compiled
kernels of :mod:`fempm.kernels.plasticity` there).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.boundary.walls import Fixed, Slip
from fempm.kernels import lumped as kl
from fempm.kernels.shape import AVAILABLE
from fempm.materials.base import IsotropicElastic
from fempm.materials.linear_elastic import LinearElastic
from fempm.materials.neo_hookean import NeoHookean
from fempm.stepping.laws import law_stress
from fempm.stepping.loads import external_forces
from fempm.stepping.nodal import kept_nodal_array, sum_ghosts
from fempm.transfer.centres import NodalCentres
from fempm.transfer.mapping import SUPPORT_TOL, mass_centres

if TYPE_CHECKING:
    from fempm.stepping.solver import ExplicitSolver


#: steps between two sorts of the particles by cell
SORT_EVERY = 100
#: a given dt at most this fraction of the bound of the stable time needs no exact check
#: (the bound's own rounding)
BOUND_SAFETY = 1.0 - 1e-12


def supported(solver: ExplicitSolver) -> bool:
    """Whether ``solver``'s options, space and mesh take a compiled step (lumped, or
    consistent: :mod:`fempm.stepping.consistent`)."""
    opts, V = solver.options, solver.V
    el = V.element.basix_element
    geo = solver.particles.locator.geometry
    return (AVAILABLE and opts.mass_mode in ("lumped", "consistent") and getattr(opts.particle_domain, "name", "") == "point"
            and el.degree == 1 and V.dofmap.index_map_bs == solver.particles.gdim and geo.affine)


def _law(mat) -> tuple[int, float, float, float]:
    """(compiled law code, lambda, mu, P-wave modulus or 0) of a material."""

    code = {NeoHookean: kl.NEO_HOOKEAN, LinearElastic: kl.LINEAR_ELASTIC}.get(type(mat), 0)
    lam, mu = mat.lame if code else (0.0, 0.0)
    wave = isinstance(mat, IsotropicElastic) and type(mat).wave_speed is IsotropicElastic.wave_speed
    modulus = sum(mat.lame) + mat.lame[1] if wave else 0.0
    return code, lam, mu, modulus


class LumpedPointStep:
    """The compiled lumped step of an :class:`~fempm.stepping.ExplicitSolver` (see the module)."""

    def __init__(self, solver: ExplicitSolver):
        self.solver = solver
        self.options = solver.options
        p, V = solver.particles, solver.V
        geo = p.locator.geometry
        self.K = geo._K
        self.kernels = kl.kernels_for(geo.cell_name)
        self.cell_dofs = np.ascontiguousarray(V.dofmap.list, dtype=np.int32)
        self.index_map = V.dofmap.index_map
        self.num_owned = self.index_map.size_local
        self.num_dofs = self.num_owned + self.index_map.num_ghosts
        d = self.d = p.gdim
        self.free = np.ones((self.num_dofs, d), dtype=np.bool_)  # (dof, component) solved for
        if solver._fixed_dofs is not None:
            self.free[solver._fixed_dofs] = False
        for c, dofs in enumerate(solver._slip_components or ()):
            self.free[dofs, c] = False
        laws = [_law(m) for m in solver.materials]
        self.law = np.array([a[0] for a in laws], dtype=np.int64)
        self.lam = np.array([a[1] for a in laws])
        self.mu = np.array([a[2] for a in laws])
        self.modulus = np.array([a[3] for a in laws])
        self.all_modulus = bool(np.all(self.modulus > 0))
        self.any_external = bool(np.any(self.law == 0))
        self.x0 = geo._x0
        self._since_sort = SORT_EVERY  # sort on the first step
        # every boundary condition a zero component, held by `free`: one fused grid pass
        self.fused = all(isinstance(bc, Fixed) or (isinstance(bc, Slip) and bc.axis is not None)
                         for bc in solver.bcs)
        self._nodal = self._nodal_array(1 + 2 * d)  # [m | m v | f]
        self._nodal_d = self._nodal_array(d)  # USF's forces, MUSL's re-mapped momenta
        # walls that check contact by position: the first mass moments sum_p M_p N_ip x_p
        self._moments = self._nodal_array(d) if solver.needs_positions else None
        self._checked: tuple | None = None  # identities of the state arrays checked finite

    # -- pieces -------------------------------------------------------------------------------
    def _nodal_array(self, k: int):
        return kept_nodal_array(self.index_map, k)

    def _wave_speeds(self) -> npt.NDArray:
        """Wave speeds of the particles whose law has no P-wave modulus (empty if none has)."""
        s = self.solver
        p = s.particles
        if self.all_modulus:
            return np.zeros(0)
        c = np.zeros(len(p))
        rho = p.mass / p.volume
        for b, (mat, idx) in enumerate(s._material_loop()):
            if self.modulus[b] <= 0:
                c[idx] = mat.wave_speed(p.fields["F"][idx], rho[idx])
        return c

    def _external(self, t: float) -> tuple[npt.NDArray, npt.NDArray]:
        """(constant body force g (d,), per-particle external forces (n or 0, d))."""
        s = self.solver
        loads = s.loads
        s._count_terms()
        if loads.traction is None and (loads.body_force is None or not callable(loads.body_force)):
            g = np.zeros(self.d) if loads.body_force is None else np.asarray(loads.body_force, dtype=np.float64)
            if g.shape != (self.d,):
                raise ValueError(f"the body force has shape {g.shape}, expected ({self.d},)")
            return g, np.zeros((0, self.d))
        return np.zeros(self.d), np.ascontiguousarray(external_forces(loads, s.particles, t))

    def _scatter(self, nodal, g, fext, cm: int, cv: int, cf: int, stable: str = ""):
        """P2G of the chosen columns into the kept ``nodal`` (vector, array), summed over
        ranks; with ``stable`` ("exact" or "bound") also this rank's stable time of the state
        or a lower bound of it (:func:`fempm.kernels.lumped._scatter_kernel`; else inf)."""
        s = self.solver
        p = s.particles
        f = p.fields
        vec, out = nodal
        out.fill(0.0)
        h, c = (s.h_cell, self._wave_speeds()) if stable else (np.zeros(0), np.zeros(0))
        local = self.kernels.scatter(p.cells, p.X, self.K, self.cell_dofs, p.mass, f["v"], p.volume, f["sigma"], g,
                                     fext, out, cm, cv, cf, h, f["body"], self.modulus, c, bound=stable == "bound")
        sum_ghosts(vec)
        return out, local

    def _centroids(self, nodal) -> NodalCentres | None:
        r"""The nodal centres of mass :math:`\sum_p M_p N_{ip} x_p / m_i` (one more particle
        pass) and masses when a wall checks contact by position, else None."""
        if self._moments is None:
            return None
        p = self.solver.particles
        f = p.fields
        vec, out = self._moments
        out.fill(0.0)
        self.kernels.scatter(p.cells, p.X, self.K, self.cell_dofs, p.mass, p.x, p.volume, f["sigma"], np.zeros(self.d),
                             np.zeros((0, self.d)), out, -1, 0, -1, np.zeros(0), f["body"], self.modulus, np.zeros(0))
        sum_ghosts(vec)
        return NodalCentres(mass_centres(nodal[:, 0], out), nodal[:, 0])

    def _stable_time(self) -> float:
        r"""The stable time of the state, :math:`\min_p h_{c(p)} / (c_p + |v_p|)` over all ranks."""
        s = self.solver
        p = s.particles
        f = p.fields
        local = self.kernels.scatter(p.cells, p.X, self.K, self.cell_dofs, p.mass, f["v"], p.volume, f["sigma"],
                                     np.zeros(self.d), np.zeros((0, self.d)), np.zeros((0, 0)), -1, -1, -1, s.h_cell,
                                     f["body"], self.modulus, self._wave_speeds())
        return -p.comm.allreduce(-local, op=MPI.MAX)

    def _g2p(self, v_new, v_old, dt, *, blend: bool, kinematics: bool, move: bool, remap=None):
        """One particle pass (:func:`fempm.kernels.lumped.kernels_for`); checks J (collective)
        after a kinematics pass; returns (#non-finite particles, which left their cells and
        are not in an owned neighbour (a moving pass; else an empty mask))."""

        s = self.solver
        p = s.particles
        f = p.fields
        opts = s.options
        external = kinematics and self.any_external
        L = np.empty((len(p) if external else 0, self.d, self.d))
        left = np.empty(len(p) if move else 0, dtype=np.bool_)
        counts = self.kernels.g2p_update(p.cells, p.X, self.K, self.cell_dofs, v_new, v_old, float(opts.flip),
                                         float(dt), blend, kinematics, move, opts.position == "particle", p.x, f["v"],
                                         f["F"], f["volume0"], p.volume, f["sigma"], f["body"], self.law, self.lam,
                                         self.mu, L, self.x0, p.locator.tol, left, *p.locator.vertex_star(), p.mass,
                                         remap if remap is not None else np.zeros((0, self.d)))
        nonfinite_j, inverted, jmin, jmax, nonfinite = counts
        if kinematics:
            flags = np.array([nonfinite_j, inverted, -jmin, jmax], dtype=float)
            p.comm.Allreduce(MPI.IN_PLACE, flags, op=MPI.MAX)
            if flags[0]:
                s._fail(f"non-finite state (deformation gradient) at particle(s) {s._ids(~np.isfinite(p.volume))}")
            if flags[1]:
                s._fail(f"inverted deformation J <= 0 at particle(s) {s._ids(p.volume <= 0)}")
            s.j_range = (-float(flags[2]), float(flags[3]))
            if external:  # laws without a compiled kernel
                rho = p.mass / p.volume
                for b, (mat, idx) in enumerate(s._material_loop()):
                    if self.law[b] == 0 and len(idx):
                        f["sigma"][idx] = law_stress(mat, f["F"][idx], L[idx], f["sigma"][idx], dt, rho[idx], f, idx)
                        nonfinite += int(np.count_nonzero(~np.isfinite(f["sigma"][idx]).all(axis=(1, 2))))
        return nonfinite, left

    # -- the grid: lumped here, consistent in fempm.stepping.consistent ----------------------------
    def _stable_factor(self, nodal, need: bool) -> float:
        """Called after P2G: what the stable time of the state is multiplied by (1: lumped)."""
        return 1.0

    def _grid_velocity(self, mass, mom, cv: int, active_min: float, guess=None, centroids=None) -> npt.NDArray:
        """Grid velocity from the nodal momenta ``mom[:, cv:cv+d]``, constrained (``centroids``:
        the nodal centres of mass for the walls that need them)."""
        v = np.empty((self.num_dofs, self.d))
        kl.grid_velocity(mass, mom, cv, self.free, active_min, v)
        self.solver._apply_bcs(v, centroids)
        return v

    def _advance(self, mass, force, cf: int, active_min: float, weak_max: float, dt: float,
                 v_old: npt.NDArray, centroids=None) -> npt.NDArray:
        r""":math:`v^+ = v + \Delta t\, a` from the nodal forces ``force[:, cf:cf+d]``, constrained."""
        v_new = np.empty((self.num_dofs, self.d))
        kl.grid_advance(mass, force[:, cf:cf + self.d], self.free, active_min, weak_max, float(dt),
                        float(self.solver.options.damping), v_old, v_new)
        self.solver._apply_bcs(v_new, centroids)
        return v_new

    def _grid_update(self, nodal, cf: int, active_min: float, weak_max: float, dt: float) -> tuple:
        """(v, v^+): :meth:`_grid_velocity` and :meth:`_advance` in one pass over the dofs, where
        every boundary condition is a zero component (:attr:`fused`)."""
        v_old, v_new = np.empty((self.num_dofs, self.d)), np.empty((self.num_dofs, self.d))
        kl.grid_update(nodal, 1, cf, self.free, active_min, weak_max, float(dt), float(self.options.damping),
                       v_old, v_new)
        return v_old, v_new

    def _state(self) -> tuple:
        """Identities of the particle arrays the passes read and check."""
        p = self.solver.particles
        f = p.fields
        return id(p.x), id(f["v"]), id(f["sigma"]), id(f["F"]), id(f["body"])

    # -- the step -----------------------------------------------------------------------------
    def step(self, dt: float | None, dt_max: float) -> float:
        s = self.solver
        opts = s.options
        p = s.particles
        d = self.d
        if p.comm.allreduce(self._state() != self._checked, op=MPI.LOR):  # arrays set from outside (any rank)
            s._check_fields()  # collective; the passes check their own results
            s._check_finite()
            s._check_bodies()
        if self._since_sort >= SORT_EVERY:
            p.sort_by_cell()
            self._since_sort = 0
        self._since_sort += 1
        g, fext = self._external(s.t)
        usf = opts.scheme == "USF"
        # a given dt is checked against a lower bound of the stable time, and against the time
        # itself only where the bound does not show it stable
        nodal, local = self._scatter(self._nodal, g, fext, 0, 1, -1 if usf else 1 + d,
                                     stable="exact" if dt is None else "bound")
        top = np.array([nodal[: self.num_owned, 0].max(initial=0.0), -local])
        p.comm.Allreduce(MPI.IN_PLACE, top, op=MPI.MAX)  # one collective: the largest mass and the stable time
        top, state = float(top[0]), -float(top[1])
        factor = self._stable_factor(nodal, dt is None)
        if dt is not None and not dt <= state * BOUND_SAFETY * factor:
            state = self._stable_time()
        dt = s._time_step(opts.cfl * state * factor, dt, dt_max)
        active_min, weak_max = SUPPORT_TOL * top, opts.mass_cutoff * top
        centroids = self._centroids(nodal)
        if self.fused and not usf:
            v_old, v_new = self._grid_update(nodal, 1 + d, active_min, weak_max, dt)
        else:
            v_old = self._grid_velocity(nodal[:, :1], nodal, 1, active_min, s.grid_velocity, centroids)
            force, cf = nodal, 1 + d
            if usf:  # stress from the mapped velocity, then the forces
                nonfinite = self._g2p(v_old, v_old, dt, blend=False, kinematics=True, move=False)[0]
                force, cf = self._scatter(self._nodal_d, g, fext, -1, -1, 0)[0], 0
            v_new = self._advance(nodal[:, :1], force, cf, active_min, weak_max, dt, v_old, centroids)
        if opts.scheme == "MUSL":  # blend, re-map the momenta, then the kinematics and motion
            vec, mom = self._nodal_d
            mom.fill(0.0)
            self._g2p(v_new, v_old, dt, blend=True, kinematics=False, move=False, remap=mom)
            sum_ghosts(vec)
            v_new = self._grid_velocity(nodal[:, :1], mom, 0, active_min, None, centroids)
            nonfinite, left = self._g2p(v_new, v_new, dt, blend=False, kinematics=True, move=True)
        elif usf:
            more, left = self._g2p(v_new, v_old, dt, blend=True, kinematics=False, move=True)
            nonfinite += more
        else:
            nonfinite, left = self._g2p(v_new, v_old, dt, blend=True, kinematics=True, move=True)
        if p.comm.allreduce(nonfinite):
            s._check_finite()  # names the particles
        s.t += dt
        s.step_count += 1
        p.relocate(left=left)
        self._checked = self._state()
        s.grid_velocity = v_new[: self.num_dofs]
        return dt
