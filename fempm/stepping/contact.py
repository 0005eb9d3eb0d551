r"""Contact between bodies: one grid velocity field per body, corrected where bodies meet.

With :class:`Contact` (``ExplicitSolver(contact=Contact(...))``) every particle group :math:`g`
(the values of ``fields[contact.field]``, by default the material index ``body``) maps to its
own nodal mass, momentum and force (Bardenhagen, Brackbill and Sulsky 2000; Bardenhagen et al.
2001),

.. math::
    m_i^g = \sum_{p \in g} M_p N_{ip}, \quad p_i^g = \sum_{p \in g} M_p v_p N_{ip}, \quad
    f_i^g = \sum_{p \in g} \big(-V_p \sigma_p \nabla N_{ip} + N_{ip} f^{ext}_p\big),

and moves with its own velocity :math:`v_i^g` (:class:`ContactGrid`). At a *contact node*
(two or more groups with mass) the outward normal of group :math:`g` comes from the mass
gradients :math:`g_i^g = \sum_{p \in g} M_p \nabla N_i(x_p)`,
:math:`\hat n_i^g = (g_i^g - \sum_{h \ne g} g_i^h) / |\cdot|`, and :func:`correct` applies
non-penetration and Coulomb friction against the centre-of-mass velocity
:math:`v_i^{cm} = \sum_g m_i^g v_i^g / \sum_g m_i^g`: with :math:`w = v^g - v^{cm}`,
:math:`w_n = w \cdot \hat n^g`, :math:`w_t = w - w_n \hat n^g`, a group approaching the others
(:math:`w_n > 0`) takes

.. math::
    v^g \leftarrow v^{cm} \ \text{(stick, } \mu w_n \ge |w_t|\text{)}, \qquad
    v^g \leftarrow v^g - w_n \hat n^g - \mu w_n \frac{w_t}{|w_t|} \ \text{(slip)},

and a separating group is left free; for two groups the corrections cancel, so every node's
momentum is kept. The correction acts on the updated velocities, not on the mapped (or
MUSL's re-mapped) ones, so that the FLIP increment :math:`v^g_{new} - v^g_{old}` carries the
whole contact impulse to the particles; each particle takes its own group's field in G2P.

* ``gap``: a group is corrected only where it touches the others, the position check of Nairn,
  Bardenhagen and Smith (2018): the others' nodal centre of mass lies less than ``gap`` ahead
  of the group's own along its normal at the end of the step,
  :math:`(\bar x_i^{o} - \bar x_i^{g}) \cdot \hat n_i^g - \Delta t\, \dot\delta_i < \text{gap}`.
* ``rigid`` groups: prescribed motion and infinite mass; their velocity replaces
  :math:`v^{cm}` and their own normal :math:`-g^r/|g^r|` the mass-gradient one. With a gap,
  the nodes of a group touching a rigid body and approaching it share the normal momentum
  it takes over each patch of touching nodes by depth (:class:`fempm.boundary.patches.Patches`),
  :math:`\Delta w_{n,i} = P \delta_i / \sum_{j \in A} m^g_j \delta_j`, as a frictional wall does.
* Consistent mass and FMPM: each group's own mass (its particles only) with lumped rows at
  the contact nodes when the contact has friction; the correction stays node-local with the
  groups' lumped masses. The stable step is the lumped one times
  :math:`\sqrt{0.8 \min_g \lambda_{min}(M_L^{g,-1} M^g)}`.
* ``mass_cutoff``: a node where a group has less than this fraction of the largest nodal mass
  gives that group no force update there.

USL and MUSL, every particle domain (CPDI2 corners move with their own body's field), any
number of ranks. What each choice above was measured to do (the rolling disk, the sliding
block, the colliding disks, the energy of MUSL with contact) is in ``docs/contact.md``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.boundary.coulomb import coulomb
from fempm.boundary.patches import Patches, depth_shares
from fempm.stepping.contact_options import Contact
from fempm.stepping.grid import BasisGrid
from fempm.stepping.state import StepState
from fempm.transfer import g2p
from fempm.transfer.centres import NodalCentres
from fempm.transfer.mapping import SUPPORT_TOL, mass_centres, p2g, p2g_gradients

__all__ = ["Contact", "ContactGrid", "correct", "particle_groups", "shared_cells"]


def correct(m: npt.NDArray, v: npt.NDArray, grad: npt.NDArray, friction: float,
            rigid: npt.NDArray | None = None, moments: npt.NDArray | None = None,
            gap: float | None = None, dt: float = 0.0,
            patches: Callable[[npt.NDArray, npt.NDArray], npt.NDArray] | None = None) -> npt.NDArray[np.bool_]:
    r"""The contact correction of the module, in place: group masses ``m`` (G, n), velocities
    ``v`` (G, n, d) and mass gradients ``grad`` (G, n, d) at n nodes; returns which nodes are
    contact nodes (two or more groups with mass). ``rigid`` (G,) bool: groups of infinite mass,
    left as they are; where one has mass it replaces the centre-of-mass velocity (where several
    have, the one with the most mass). ``gap`` with the groups' first mass moments ``moments``
    (G, n, d), :math:`\sum_p M_p N_{ip} x_p`: a group is corrected only where the others'
    nodal centre of mass lies less than ``gap`` ahead of its own along its normal at the end of
    the step ``dt``, at the present speed of approach. ``patches(dofs, values)``: the sums of
    ``values`` over the patch of each of the nodes ``dofs`` (:meth:`fempm.boundary.patches.Patches.sums`,
    collective); with it and a gap, the nodes touching and approaching a rigid group share its
    normal impulse by depth (see the module); without it each node is on its own."""
    present = m > 0.0
    contact = np.count_nonzero(present, axis=0) >= 2
    rigid = np.zeros(len(m), dtype=np.bool_) if rigid is None else np.asarray(rigid, dtype=np.bool_)
    share = patches is not None and gap is not None and rigid.any()  # collective calls below
    if not contact.any() and not share:
        return contact
    total = m.sum(axis=0)
    vcm = np.einsum("gn,gnd->nd", m, v) / np.where(total > 0, total, 1.0)[:, None]
    on = np.zeros(len(total), dtype=np.bool_)
    top_all = np.zeros(len(total), dtype=np.int64)
    if gap is not None:
        if moments is None:
            raise ValueError("a contact gap needs the groups' mass moments")
        moment_sum = moments.sum(axis=0)
        tiny = np.finfo(float).tiny
    if rigid.any():
        rm = np.where(rigid[:, None], m, 0.0)
        on = rm.max(axis=0) > 0.0
        top_all = rm.argmax(axis=0)
        vcm[on] = v[top_all[on], on]
        rigid_normal = -grad[top_all[on], on]  # into the rigid body: its own surface, not a deformable corner
    all_grad = grad.sum(axis=0)
    for g in np.flatnonzero(~rigid):  # a loop over the groups (a few), not over nodes
        normal = 2.0 * grad[g] - all_grad  # grad m_g - sum of the others: out of group g
        if on.any():
            normal[on] = rigid_normal
        size = np.linalg.norm(normal, axis=1)
        at = np.flatnonzero(contact & present[g] & (size > 0.0))
        n = normal[at] / size[at, None]
        w = v[g, at] - vcm[at]
        wn = np.einsum("nd,nd->n", w, n)
        wt = w - wn[:, None] * n
        held = wn > 0.0  # approaching: gives up its normal velocity wn (node by node) ...
        dwn = wn.copy()
        if gap is not None:  # ... where it touches: the others' centre of mass within gap of its own
            own = moments[g, at] / m[g, at, None]
            others = np.maximum(total[at] - m[g, at], tiny)
            rest = (moment_sum[at] - moments[g, at]) / others[:, None]
            closing = wn * total[at] / others  # the normal speed of approach to the others
            r = np.flatnonzero(on[at])  # where a rigid body is, its own centre of mass and speed
            k = top_all[at[r]]
            rest[r] = moments[k, at[r]] / m[k, at[r], None]
            closing[r] = wn[r]
            depth = gap - (np.einsum("nd,nd->n", rest - own, n) - dt * closing)
            held &= depth > 0.0
            if share:  # at a rigid body the approaching nodes share their patch's impulse by depth
                r = r[depth[r] > 0.0]  # the touching nodes: a patch is a connected set of them
                dwn[r] = depth_shares(patches, at[r], m[g, at[r]], np.where(held[r], wn[r], 0.0),
                                      np.where(held[r], depth[r], 0.0))  # separating ones take no share
        h = np.flatnonzero(held)  # stick or slip against the centre of mass (wn - dwn: 0 node by node)
        v[g, at[h]] = vcm[at[h]] + coulomb(wt[h], wn[h], n[h], dwn[h], friction)
    return contact


def particle_groups(contact: Contact, particles) -> tuple[npt.NDArray[np.int64], int]:
    """(each particle's group of ``fields[contact.field]``, the number of groups G over all
    ranks), checked: non-negative integers, every rigid group present (collective)."""
    fld, comm = particles.fields, particles.comm
    if contact.field not in fld:
        raise ValueError(f"contact: the particles have no field {contact.field!r} naming their groups")
    group = np.asarray(fld[contact.field])
    if group.ndim != 1:
        bad = 1
    elif group.dtype.kind in "iu":
        bad = int(group.min(initial=0) < 0)
    else:
        bad = int(np.count_nonzero((group < 0) | (group != np.round(group))))
    bad = comm.allreduce(bad)
    if bad:
        raise ValueError(f"contact: fields[{contact.field!r}] must hold one non-negative integer group per particle")
    group = group.astype(np.int64)
    G = comm.allreduce(int(group.max(initial=-1)) + 1, op=MPI.MAX)
    if contact.rigid:
        present = np.zeros(max(G, max(contact.rigid) + 1), dtype=np.int64)
        present[:G] = np.bincount(group, minlength=G)
        comm.Allreduce(MPI.IN_PLACE, present, op=MPI.SUM)
        absent = [g for g in contact.rigid if present[g] == 0]
        if absent:
            raise ValueError(f"contact: rigid group(s) {absent} hold no particle (fields[{contact.field!r}] has the "
                             f"groups {np.flatnonzero(present).tolist()})")
    return group, G


def shared_cells(particles, field: str) -> int:
    """The number of cells holding particles of two or more groups of ``fields[field]`` (bodies
    that have not come apart; collective: each particle lives on the rank owning its cell)."""
    pairs = np.unique(np.stack([particles.cells, np.asarray(particles.fields[field])]), axis=1)
    _, groups = np.unique(pairs[0], return_counts=True)
    return particles.comm.allreduce(int(np.count_nonzero(groups > 1)))


class ContactGrid(BasisGrid):
    """A velocity field per particle group of ``state.contact``, corrected where groups meet
    (see the module); numpy stages on the particle basis, the schemes USL and MUSL."""

    def __init__(self, state: StepState):
        super().__init__(state)
        if not self.options.stages.forces_with_map:
            raise ValueError(f"contact supports the schemes USL and MUSL (got {self.options.stages})")
        self.contact = state.contact

    def groups(self) -> npt.NDArray[np.int64]:
        """Each particle's group, checked (:func:`particle_groups`)."""
        group, self.num_groups = particle_groups(self.contact, self.state.particles)
        return group

    def open(self, dt: float | None) -> float:
        s, opts, contact = self.state, self.options, self.contact
        p = s.particles
        self.basis = basis = self.open_basis()
        group = self.groups()
        G = self.num_groups
        self.masks = masks = [group == g for g in range(G)]
        self.rigid = rigid = np.isin(np.arange(G), contact.rigid)
        self.deformable = deformable = np.flatnonzero(~rigid)
        m = np.stack([p2g(basis, (p.mass * k)[:, None])[:, 0] for k in masks])
        self.total = total = m.sum(axis=0)
        top = p.comm.allreduce(float(total[: basis.index_map.size_local].max(initial=0.0)), op=MPI.MAX)
        has = m > SUPPORT_TOL * top
        # consistent mass or FMPM: each deformable group's own mass (its masses, zeros elsewhere), with
        # lumped rows at the contact nodes where friction acts (see the module)
        shared = np.count_nonzero(has, axis=0) >= 2 if contact.friction > 0.0 else None
        self.ops = {} if not opts.mass_model.couples_dofs else {
            g: self.mass_operator(basis, p.mass * masks[g], lump_dofs=shared) for g in deformable}
        stable = self.stable_with(list(self.ops.values()))
        d = p.gdim
        self.grad = np.stack([p2g_gradients(basis, (p.mass * k)[:, None, None] * np.eye(d)) for k in masks])
        s.count_terms()
        self.force = np.zeros_like(self.grad)
        fext = self.external()  # once for every group
        for g in deformable:  # rigid groups take no forces
            self.force[g] = self.internal_and_external(basis, fext, masks[g].astype(np.float64))
        self.m_has = np.where(has, m, 0.0)
        self.inv = np.where(has, 1.0 / np.where(has, m, 1.0), 0.0)[:, :, None]
        # per group: a node with a sliver of one body's mass keeps its mapped velocity (a_g = f_g / m_g
        # there is large where the other body's mass keeps the node from counting as weak)
        self.weak = m <= max(opts.mass_cutoff, contact.mass_cutoff) * top
        # walls that check contact by position see each group's own centre of mass
        self.moments = None
        self.centroids = [None] * G
        if s.conditions.needs_positions or contact.gap is not None:  # each group's first mass moment
            self.moments = np.stack([p2g(basis, (p.mass * k)[:, None] * p.x) for k in masks])
            if s.conditions.needs_positions:
                self.centroids = [NodalCentres(c, mg) for c, mg in zip(mass_centres(m, self.moments), m)]
        return stable

    def constrain(self, v: npt.NDArray, dt: float | None = None) -> npt.NDArray:
        """Each deformable group's grid conditions, and the ghost values, in place (``dt``: of
        the update ``v`` is, for the dashpots)."""
        for g in range(self.num_groups):
            if not self.rigid[g]:
                self.state.conditions.apply(v[g], self.centroids[g], dt)
            v[g] = self.basis.update_ghosts(v[g])
        return v

    def velocity(self, remapped: bool = False) -> npt.NDArray:
        """Each group's velocity from its particles' momenta (its mass solve). The mapped
        velocities are not corrected: the FLIP increment v_new - v_old then carries the whole
        contact impulse of the step to the particles (and MUSL's re-mapped ones are not
        corrected again)."""
        p = self.state.particles
        self.momentum = mom = [p2g(self.basis, (p.mass * k)[:, None] * p.fields["v"]) for k in self.masks]
        return self.constrain(np.stack([self.ops[g].solve(mom[g]) if g in self.ops else mom[g] * self.inv[g]
                                        for g in range(self.num_groups)]))

    def advance(self, v_old: npt.NDArray, dt: float) -> npt.NDArray:
        opts, contact = self.options, self.contact
        a = self.force * self.inv
        for g, op in self.ops.items():
            a[g] = self.accelerations(op, self.force[g])
        if opts.damping > 0.0:
            a -= opts.damping * v_old
        a[self.weak] = 0.0
        a[self.rigid] = 0.0
        v_new = v_old + dt * a
        patches = Patches.of_space(self.basis.V, index_map=self.basis.index_map).sums if self.rigid.any() else None
        correct(self.m_has, v_new, self.grad, contact.friction, self.rigid, self.moments, contact.gap, dt, patches)
        return self.constrain(v_new, dt)

    def to_particles(self, v_new: npt.NDArray, v_old: npt.NDArray, dt: float, *, blend: bool = False,
                     kinematics: bool = False, move: bool = False, remap: bool = False) -> None:
        """Every particle takes its own group's field; rigid particles keep their velocity and
        deformation (L = 0) and move with that velocity."""
        p = self.state.particles
        fld = p.fields
        d = p.gdim
        vp, at_grid, L = fld["v"].copy(), fld["v"].copy(), np.zeros((len(p), d, d))
        if blend:
            self.record_reaction(v_new, v_old, dt)
        for g in self.deformable:
            k = self.masks[g][:, None]
            if blend:
                blended, grid_v, grads = g2p.blend(self.basis, v_new[g], v_old[g], fld["v"], self.options.velocity_transfer.blend)
                np.copyto(vp, blended, where=k)  # the group's rows (no fancy-indexed copies)
            else:
                grid_v, grads = g2p.velocity_and_gradient(self.basis, v_new[g])
            np.copyto(at_grid, grid_v, where=k)
            np.copyto(L, grads, where=k[:, :, None])
        if blend:
            fld["v"] = vp
        if kinematics:
            self.update_kinematics(L, dt)
        if move:
            self.move(at_grid, lambda: self.corner_velocity(v_new), dt)

    def reaction_fields(self, v_new: npt.NDArray, v_old: npt.NDArray) -> list[tuple]:
        """The deformable groups' fields (rigid ones take no conditions)."""
        return [(self.m_has[g], self.momentum[g], self.force[g], v_old[g], v_new[g], ~self.weak[g])
                for g in self.deformable]

    def corner_velocity(self, v_new: npt.NDArray) -> npt.NDArray:
        """Each body's corners move with its own field, rigid ones rigidly."""
        fld = self.state.particles.fields
        corner_velocity = np.repeat(fld["v"][:, None, :], fld["corners"].shape[1], axis=1)
        for g in self.deformable:
            k = self.masks[g]
            corner_velocity[k] = self.basis.gather_samples(v_new[g])[k]
        return corner_velocity

    def nodal(self, v: npt.NDArray) -> npt.NDArray:
        """The centre-of-mass velocity of the groups at each node (the space's dofs)."""
        mom = np.einsum("gn,gnd->nd", self.m_has, v)
        return (mom / np.where(self.total > 0, self.total, 1.0)[:, None])[: self.basis.num_dofs_space]
