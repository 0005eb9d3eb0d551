r"""Multi-field contact of point particles in compiled passes (:class:`ContactPointGrid`).

The contact of :mod:`fempm.stepping.contact` (same equations, options and checks;
:class:`~fempm.stepping.contact.ContactGrid` is the reference it is tested against to
round-off) on the passes of :class:`~fempm.stepping.lumped.PointGrid`: each particle adds to,
and reads from, the columns of its own group in one nodal array with a block of columns per
group (the ``group`` argument of :func:`fempm.kernels.lumped.kernels_for`'s passes),

.. math::
    [\, m^g \mid m^g v^g \mid f^g \mid \nabla m^g \,]_{g = 0 \dots G-1}, \qquad
    \nabla m_i^g = \sum_{p \in g} M_p \nabla N_{ip},

so that the mass, momenta, forces and mass gradients of every group come from one P2G pass
(ghosts summed once), and G2P (blend, MUSL's re-map, kinematics, motion and the state's sums)
stays one pass. Where every boundary condition holds velocity components at 0 and no group is
rigid, the grid update and the correction are one compiled pass over the dofs
(:mod:`fempm.kernels.contact`); otherwise the grid takes the numpy stages on the (G, dofs)
views of that array (:func:`~fempm.stepping.contact.correct`). With a ``gap`` or a wall that checks contact by
position, one more pass maps each group's first mass moments.

The particles of a rigid group keep their velocity and deformation and move with their
velocity, in the same passes. With consistent mass each deformable group solves with its own
matrix, :math:`m^g_{ij} = \sum_{p \in g} M_p N_{ip} N_{jp}` (a
:class:`~fempm.stepping.consistent.ConsistentNodalMass` per group: its mass pass takes the group's
particle masses, zero for the others), with lumped rows at the contact nodes where the contact
has friction; its velocity and acceleration solves replace the lumped divisions, the correction
stays node-local on the groups' lumped masses and the stable step is the lumped one times
:math:`\sqrt{0.8 \min_g \lambda_{min}(M_L^{g,-1} M^g)}`, as :class:`~fempm.stepping.contact.ContactGrid`.
Applies to point particles with lumped or consistent mass on the spaces of the compiled passes,
USL and MUSL (FMPM mass with contact, and particle domains, take
:class:`~fempm.stepping.contact.ContactGrid`).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.boundary.patches import Patches
from fempm.kernels import contact as kc
from fempm.kernels.bundles import Basis, GridStep, Groups, Moves, Outputs, State
from fempm.stepping.contact import correct, particle_groups
from fempm.stepping.lumped import BOUND_SAFETY, PointGrid
from fempm.stepping.state import StepState
from fempm.transfer.centres import NodalCentres
from fempm.transfer.mapping import SUPPORT_TOL, mass_centres
from fempm.stepping.consistent import ConsistentNodalMass
from fempm.transfer.mass_models import Consistent, Lumped

__all__ = ["ContactPointGrid"]


class ContactPointGrid(PointGrid):
    """A velocity field per particle group of ``state.contact``, corrected where groups meet
    (:mod:`fempm.stepping.contact`), in the compiled passes (see the module)."""

    takes = "contact with point particles, lumped or consistent mass, USL or MUSL, on a space of the compiled passes"

    @classmethod
    def refusal(cls, state: StepState) -> str | None:
        """Why ``state``'s contact does not take this grid (None where it does): the options,
        space and mesh of a :class:`~fempm.stepping.lumped.PointGrid` with lumped or consistent
        mass, USL or MUSL."""
        reason = PointGrid.refusal(state)
        if reason is not None:
            return reason
        if type(state.options.mass_model) not in (Lumped, Consistent):
            return f"mass {state.options.mass_model.label} with contact: lumped or consistent"
        if not state.options.stages.forces_with_map:
            return f"scheme {state.options.stages.name} with contact: USL or MUSL"
        return None

    def __init__(self, state: StepState):
        super().__init__(state)
        self.contact = state.contact
        self.num_groups = 0
        #: the number of contact nodes (two or more groups with mass) of the last grid update, on this rank
        self.contacts = 0
        rigid = bool(self.contact.rigid)
        #: consistent mass: each deformable group's own (by group index, made as groups appear)
        self.consistent = type(self.options.mass_model) is Consistent
        self.group_masses: dict[int, ConsistentNodalMass] = {}
        # the grid update in one compiled pass over the dofs: walls holding zero components, no rigid
        # group (with consistent mass, after the groups' solves)
        self.fused = self.conditions.zero_components and not rigid
        self.positions = self.conditions.needs_positions or self.contact.gap is not None
        self.all_free = np.ones_like(self.free)
        # with a gap, the nodes touching a rigid body share its impulse over their patches
        self.patches = Patches.of_space(state.V, index_map=self.index_map).sums if rigid else None

    def _layout(self, G: int) -> None:
        """The kept nodal arrays for ``G`` groups: [m | m v | f | grad m] (``stride`` columns)
        per group, and d columns per group for MUSL's re-mapped momenta and the mass moments."""
        if G == self.num_groups:
            return
        d = self.d
        self.num_groups, self.stride = G, 1 + 3 * d
        self.rigid = np.isin(np.arange(G), self.contact.rigid)
        self._nodal = self.nodal_array(G * self.stride)
        self._nodal_d = self.nodal_array(G * d)
        self._moments = self.nodal_array(G * d) if self.positions else None

    def _by_group(self, array: npt.NDArray, start: int, k: int) -> npt.NDArray:
        """The (G, dofs, k) view of columns ``start:start+k`` of each group's block of ``array``."""
        G = self.num_groups
        return array.reshape(len(array), G, -1)[:, :, start:start + k].transpose(1, 0, 2)

    def open(self, dt: float | None) -> float:
        s, opts, contact = self.state, self.options, self.contact
        p = s.particles
        d = self.d
        self.group, G = particle_groups(contact, p)
        self._layout(G)
        self.external = self._external(s.t)
        out, local = self._scatter(self._nodal, self.external, 0, 1, 1 + d, stable="exact" if dt is None else "bound",
                                   groups=Groups(self.group, self.stride, self.rigid), cg=1 + 2 * d)
        top = np.array([kc.largest_total(out, self.stride, G, self.num_owned), -local])
        p.comm.Allreduce(MPI.IN_PLACE, top, op=MPI.MAX)  # one collective: the largest mass and the stable time
        top, state = float(top[0]), -float(top[1])
        if dt is not None and not dt <= state * BOUND_SAFETY:
            state = self._stable_time()
        # a node with a sliver of one group's mass keeps that group's mapped velocity
        self.active_min, self.weak_max = SUPPORT_TOL * top, max(opts.mass_cutoff, contact.mass_cutoff) * top
        m = self._by_group(out, 0, 1)[:, :, 0]  # (G, dofs)
        self.moments, self.centroids = self._group_moments(m)
        factor = self._group_systems(out, m, dt is None, top) if self.consistent else 1.0
        if not self.fused or self.consistent:  # the numpy stages' (G, dofs) arrays
            has = m > self.active_min
            self.m_has = np.where(has, m, 0.0)
            self.inv = np.where(has, 1.0 / np.where(has, m, 1.0), 0.0)[:, :, None]
            self.weak = m <= self.weak_max
            self.force, self.grad = self._by_group(out, 1 + d, d), self._by_group(out, 1 + 2 * d, d)
        self.nonfinite, self.left = 0, None
        return opts.cfl * state * factor

    def _group_systems(self, out: npt.NDArray, m: npt.NDArray, need: bool, top: float) -> float:
        r"""Each deformable group's consistent matrix of this step (its mass pass over the group's
        particle masses; rows lumped at the contact nodes, two or more groups with mass, where the
        contact has friction); returns the smallest stable-step factor
        :math:`\sqrt{0.8\,\lambda_{min}}` of the groups (recorded: the smallest ratio)."""
        s = self.state
        p = s.particles
        shared = None
        if self.contact.friction > 0.0:
            shared = np.count_nonzero(m > self.active_min, axis=0) >= 2
        factors, ratios = [1.0], []
        for g in np.flatnonzero(~self.rigid):
            mass = self.group_masses.get(g)
            if mass is None:
                mass = self.group_masses[g] = ConsistentNodalMass(self.layout)
            masses = np.where(self.group == g, p.mass, 0.0)
            factors.append(mass.stable_factor(out[:, g * self.stride:(g + 1) * self.stride], need, top, masses,
                                              shared))
            ratios.append(mass.ratio)
        if ratios and not self.options.lumped_forces:
            s.record.mass_ratio = min(ratios)
        return min(factors)

    def _group_moments(self, m: npt.NDArray) -> tuple:
        r"""(each group's first mass moments :math:`\sum_{p \in g} M_p N_{ip} x_p` (G, dofs, d),
        each group's :class:`~fempm.transfer.centres.NodalCentres` for the walls that check
        contact by position), one more particle pass; (None, None per group) without a gap or
        such a wall."""
        if self._moments is None:
            return None, [None] * self.num_groups
        moments = self._by_group(self.mass_moments(Groups(self.group, self.d, self.rigid)), 0, self.d)
        centroids = [None] * self.num_groups
        if self.conditions.needs_positions:
            centroids = [NodalCentres(c, mg) for c, mg in zip(mass_centres(m, moments), m)]
        return moments, centroids

    def _constrain(self, v: npt.NDArray, dt: float | None = None) -> npt.NDArray:
        """Each deformable group's grid conditions on ``v`` (dofs, G d), in place (a fused
        grid's velocities hold them already; ``dt``: of the update ``v`` is, for the dashpots)."""
        if not self.fused:
            by_group = self._by_group(v, 0, self.d)
            for g in np.flatnonzero(~self.rigid):
                self.conditions.apply(by_group[g], self.centroids[g], dt)
        return v

    def velocity(self, remapped: bool = False) -> npt.NDArray:
        """Each group's velocity from its particles' momenta (the mapped ones are not corrected:
        see :meth:`fempm.stepping.contact.ContactGrid.velocity`); with consistent mass each
        deformable group's solve, constrained."""
        mom, stride, cv = (self._nodal_d[1], self.d, 0) if remapped else (self._nodal[1], self.stride, 1)
        v = np.empty((self.num_dofs, self.num_groups * self.d))
        free = self.free if self.fused else self.all_free  # (else the conditions of the deformable groups)
        kc.group_velocity(self._nodal[1], self.stride, mom, stride, cv, free, self.active_min, v)
        if not self.consistent:
            return self._constrain(v)  # (the fused grid's conditions: ``free``)
        d, nodal = self.d, self._nodal[1]
        for g, mass in self.group_masses.items():
            view = nodal[:, g * self.stride:(g + 1) * self.stride]
            v[:, g * d:(g + 1) * d] = mass.velocity(view, mom, g * stride + cv, self.active_min, None,
                                                    self.centroids[g])
        return v

    def advance(self, v_old: npt.NDArray, dt: float) -> npt.NDArray:
        """The numpy stages (conditions other than zero components, rigid groups)."""
        opts, contact = self.options, self.contact
        old = self._by_group(v_old, 0, self.d)
        v = np.empty_like(v_old)
        a = self._by_group(v, 0, self.d)  # the accelerations, then the new velocities, in place
        np.multiply(self.force, self.inv, out=a)
        nodal = self._nodal[1]
        for g, mass in self.group_masses.items():  # consistent mass: each deformable group's solve
            a[g] = mass.acceleration(nodal[:, g * self.stride:(g + 1) * self.stride], nodal,
                                     g * self.stride + 1 + self.d)
        if opts.damping > 0.0:
            a -= opts.damping * old
        a[self.weak] = 0.0
        a[self.rigid] = 0.0
        a *= dt
        a += old
        at = correct(self.m_has, a, self.grad, contact.friction, self.rigid, self.moments, contact.gap, dt,
                     self.patches)
        self.contacts = int(np.count_nonzero(at))
        return self._constrain(v, dt)

    def update(self, dt: float) -> tuple[npt.NDArray, npt.NDArray]:
        if not self.fused:  # velocity() then advance()
            return super().update(dt)
        shape = (self.num_dofs, self.num_groups * self.d)
        v_old, v_new = np.empty(shape), np.empty(shape)
        contact = self.contact
        gap = -1.0 if contact.gap is None else float(contact.gap)
        moments = self._moments[1] if self._moments is not None else np.zeros((0, 0))
        nodal, d, accelerations = self._nodal[1], self.d, None
        if self.consistent:  # the groups' solves, then the same pass from their velocities and accelerations
            v_old = self.velocity()
            accelerations = np.empty(shape)
            for g, mass in self.group_masses.items():
                accelerations[:, g * d:(g + 1) * d] = mass.acceleration(
                    nodal[:, g * self.stride:(g + 1) * self.stride], nodal, g * self.stride + 1 + d)
        self.contacts = kc.grid_update(nodal, self.stride, self.free, self.active_min, self.weak_max, float(dt),
                                       float(self.options.damping), float(contact.friction), gap, moments, v_old,
                                       v_new, accelerations=accelerations)
        return v_old, v_new

    def forces(self) -> None:  # pragma: no cover - the schemes with contact map the forces with the mass
        raise ValueError(f"contact supports the schemes USL and MUSL (got {self.options.stages})")

    def gather_pass(self, grid: GridStep, state: State, moves: Moves, outputs: Outputs, *, blend: bool,
                    kinematics: bool, move: bool) -> tuple:
        """The G2P pass, each particle with its group's field."""
        p = self.state.particles
        return self.kernels.g2p_update(Basis(p.cells, p.X, self.K, self.cell_dofs), grid, state, self.laws, moves,
                                       outputs, Groups(self.group, self.d, self.rigid), blend=blend,
                                       kinematics=kinematics, move=move)

    def reaction_fields(self, v_new: npt.NDArray, v_old: npt.NDArray) -> list[tuple]:
        """The deformable groups' fields (rigid ones take no conditions)."""
        d, nodal = self.d, self._nodal[1]
        mass, mom = self._by_group(nodal, 0, 1)[:, :, 0], self._by_group(nodal, 1, d)
        force, old, new = self._by_group(nodal, 1 + d, d), self._by_group(v_old, 0, d), self._by_group(v_new, 0, d)
        return [(mass[g], mom[g], force[g], old[g], new[g], mass[g] > self.weak_max)
                for g in np.flatnonzero(~self.rigid)]

    def nodal(self, v: npt.NDArray) -> npt.NDArray:
        """The centre-of-mass velocity of the groups at each node (owned + ghost dofs)."""
        out = np.empty((self.num_dofs, self.d))
        kc.centre_of_mass(self._nodal[1], self.stride, self.active_min, v, out)
        return out

    def checkpoint_state(self) -> tuple[dict, dict[str, npt.NDArray]]:
        """The point grid's state and, with consistent mass, each group's
        (:meth:`fempm.stepping.consistent.ConsistentNodalMass.checkpoint_state`, keys
        ``group<g>:...``)."""
        counters, arrays = super().checkpoint_state()
        for g, mass in self.group_masses.items():
            more, kept = mass.checkpoint_state()
            counters.update({f"group{g}:{k}": v for k, v in more.items()})
            arrays.update({f"group{g}:{k}": v for k, v in kept.items()})
        return counters, arrays

    def restore_state(self, counters: dict, arrays: dict[str, npt.NDArray]) -> None:
        """Restore :meth:`checkpoint_state` (collective)."""
        super().restore_state(counters, arrays)
        groups = sorted({int(k.split(":", 1)[0][5:]) for k in (*counters, *arrays) if k.startswith("group")})
        for g in groups:
            mass = self.group_masses.get(g)
            if mass is None:
                mass = self.group_masses[g] = ConsistentNodalMass(self.layout)
            prefix = f"group{g}:"
            mass.restore_state({k[len(prefix):]: v for k, v in counters.items() if k.startswith(prefix)},
                               {k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)})
