r"""Contact between bodies: one grid velocity field per body, corrected where bodies meet.

With one velocity field the bodies of a scene interact through shared nodes: they stick and,
at speed, interpenetrate. With :class:`Contact` (``ExplicitSolver(contact=Contact(...))``)
every particle group :math:`g` (the values of ``fields[contact.field]``, by default the
material index ``body``) maps to its own nodal mass, momentum and force (Bardenhagen,
Brackbill and Sulsky 2000; Bardenhagen et al. 2001),

.. math::
    m_i^g = \sum_{p \in g} M_p N_{ip}, \quad p_i^g = \sum_{p \in g} M_p v_p N_{ip}, \quad
    f_i^g = \sum_{p \in g} \big(-V_p \sigma_p \nabla N_{ip} + N_{ip} f^{ext}_p\big),

and moves with its own velocity :math:`v_i^g`. A node is a *contact node* where two or more
groups have mass. There the outward normal of group :math:`g` comes from the mass gradients
:math:`g_i^g = \sum_{p \in g} M_p \nabla N_i(x_p)` (which point from the group's particles
to the node, out of the group at its boundary),
:math:`\hat n_i^g = (g_i^g - \sum_{h \ne g} g_i^h) / |\cdot|` (for two groups the normals
are opposite, :math:`\hat n^1 = -\hat n^2`, which conserves momentum), and
:func:`correct` applies non-penetration and Coulomb friction against the centre-of-mass
velocity :math:`v_i^{cm} = \sum_g m_i^g v_i^g / \sum_g m_i^g`: with
:math:`w = v^g - v^{cm}`, :math:`w_n = w \cdot \hat n^g` and :math:`w_t = w - w_n \hat n^g`,
a group approaching the others (:math:`w_n > 0`) takes

.. math::
    v^g \leftarrow v^{cm} \ \text{(stick, } \mu w_n \ge |w_t|\text{)}, \qquad
    v^g \leftarrow v^g - w_n \hat n^g - \mu w_n \frac{w_t}{|w_t|} \ \text{(slip)},

and a separating group is left free. For two groups the corrections
:math:`m^1 \Delta v^1 = -m^2 \Delta v^2` cancel, so the node's momentum is unchanged to
round-off. The correction is applied to the updated velocities, not to the mapped ones (nor,
with MUSL, to the re-mapped ones): the FLIP increment :math:`v^g_{new} - v^g_{old}` then
carries the whole contact impulse to the particles, and each particle takes its own group's
field in G2P.
Every particle domain (a CPDI2 particle's corners move with its own group's field, a rigid
body's with its velocity), USL and MUSL, any number of ranks (the nodal sums are summed
over ranks as in the single-field step, and the correction is node-local), lumped or
consistent mass (and FMPM). With consistent mass each group has its own mass matrix
:math:`M^g_{ij} = \sum_{p \in g} M_p N_{ip} N_{jp}` and its velocity and acceleration are
the solves :math:`M^g v^g = p^g` and :math:`M^g a^g = f^g`, with lumped rows at the contact
nodes (where two or more groups have mass) when the contact has friction; the correction stays
node-local and weighs the groups by their lumped masses :math:`m^g_i = \sum_j M^g_{ij}`.
Coulomb friction acts on each node's own tangential velocity, and consistently solved
velocities oscillate from node to node: without the lumped rows some contact nodes moved
slower than mu times their normal velocity change, the friction there was cut short, and a
block on a rigid plane at 30 degrees slid 19 % faster than g (sin - mu cos) at mu = 0.5 and
slid at mu = 0.6 (FLIP 0.8, 8 cells; with the lumped rows and PIC: -0.16 % and at rest). (Frictionless contact keeps the consistent rows: two
elastic bars rebound at 95.7 % of their speed with them, 89.7 % with lumped contact rows.) Since
:math:`\sum_{ij} M^g_{ij} v^g_j = \sum_i m^g_i v^g_i`, conserving
:math:`\sum_g m^g_i v^g_i` at every node conserves the total momentum of the consistent
fields, and the FLIP increments carry it to the particles. The stable step is the lumped one
times :math:`\sqrt{0.8 \min_g \lambda_{min}(M_L^{g,-1} M^g)}`.

Velocities alone put bodies in contact one cell early: every node where two groups have mass
and approach each other is corrected, also where their surfaces are still apart, and a curved
body meets a flat one across several nodes. With ``gap`` a group is corrected only where it
touches the others, by the position check of Nairn, Bardenhagen and Smith (2018): the others'
nodal centre of mass lies less than ``gap`` ahead of the group's own along its normal at the
end of the step, :math:`(\bar x_i^{o} - \bar x_i^{g}) \cdot \hat n_i^g - \Delta t\, \dot\delta_i
< \text{gap}` (:math:`\dot\delta_i` the normal speed at which the group approaches the others), with
:math:`\bar x_i^g = \sum_{p \in g} M_p N_{ip} x_p / m_i^g` (two bodies filling the cells on
either side of a node have them :math:`2h/3` apart on a grid of spacing :math:`h`; 0.8 h is a
good gap). For two groups the test is the same for both, and momentum stays conserved.

A group listed in ``rigid`` is a rigid body of prescribed motion and infinite mass: its
particles keep their velocity (``fields["v"]``, which the scene may change between steps),
their deformation and stress, take no forces and move with that velocity; at a node where it
has mass its velocity replaces :math:`v^{cm}`, the normal is its own, :math:`\hat n = -g^r / |g^r|`
(a deformable body's mass gradient tilts at its corners, and a block's front corner then
brakes on a flat plane; Nairn's codes bias the normal to the rigid material for the same
reason), and only the other groups are corrected (the momentum they lose there goes into the
rigid body). Grid conditions do not act on it. With a ``gap`` the nodes of a group that touch a
rigid body and approach it share the normal momentum it takes over each patch of touching
nodes (a connected set, :class:`fempm.boundary.patches.Patches`, over all ranks) by depth, much as a
frictional wall does (:class:`fempm.boundary.Friction`): with :math:`w = v^g - v^r`, the depth
:math:`\delta_i = \text{gap} - ((\bar x^r_i - \bar x^g_i) \cdot \hat n - \Delta t\, w_n) > 0`
and :math:`P = \sum_j m^g_j w_{n,j}` over the patch's approaching nodes :math:`A`,

.. math::
    \Delta w_{n,i} = P\, \frac{\delta_i}{\sum_{j \in A} m^g_j \delta_j}, \qquad
    w_{n,i} \leftarrow w_{n,i} - \Delta w_{n,i}, \qquad
    w_{t,i} \leftarrow w_{t,i} \max\Big(0,\ 1 - \mu \frac{\Delta w_{n,i}}{|w_{t,i}|}\Big)
    \quad (i \in A),

and a separating node stays free. The patch takes the normal momentum it takes node by node,
centred where the body is deepest: node by node a disk turning on a rigid plane is braked by the
nodes ahead of its contact point and slid at mu = 0.2, 4 % above its rolling threshold (-1.5 %
and -2.0 % at 8 and 16 cells, docs/contact.md). Shared over every touching node (the grid
wall's rule), separating ones too, the disk rolled as well, but separating nodes were pushed off
the rigid body, and USL with GIMP domains, stable node by node, gained 20 % energy within 161
steps. Between deformable groups the correction stays node by node, which conserves every
node's momentum.

A node where a group has less than ``mass_cutoff`` (default 1 %) of the largest nodal mass
gives that group no force update there (it keeps the mapped velocity): in a single field such
a node shares the other body's mass and :math:`f/m` stays bounded; per group it does not, and
on the colliding disks USL at CFL 0.4 blows up with the single field's cut-off (1e-9) and is
stable with 1 %. With MUSL the re-mapped velocities are not corrected again (a correction the
particles' momenta do not carry adds energy, 20 % on the disks); MUSL with contact still gains
17 % energy on the disks at CFL 0.4 (11 % with a gap of 0.8 cells, 8 % with consistent mass)
and none at CFL 0.1; USL loses 14 % (3 % with consistent mass).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.boundary.patches import Patches, depth_shares
from fempm.stepping.loads import external_forces
from fempm.transfer import g2p
from fempm.transfer.centres import NodalCentres
from fempm.transfer.mapping import SUPPORT_TOL, mass_centres, p2g, p2g_gradients

if TYPE_CHECKING:
    from fempm.stepping.solver import ExplicitSolver


@dataclass(frozen=True)
class Contact:
    """Multi-velocity-field contact with Coulomb ``friction`` between the particle groups named
    by ``fields[field]`` (integers 0, 1, ...; default the material index ``body``). The groups
    in ``rigid`` are rigid bodies of prescribed motion; with a ``gap`` (a length) groups are in
    contact only where they touch (see the module)."""

    friction: float = 0.0
    field: str = "body"
    mass_cutoff: float = 1e-2
    rigid: tuple[int, ...] = ()
    gap: float | None = None

    def __post_init__(self):
        if self.gap is not None and not 0.0 < self.gap < np.inf:
            raise ValueError(f"Contact needs a finite gap > 0 or None (got {self.gap!r})")
        object.__setattr__(self, "rigid", tuple(self.rigid))
        if not all(isinstance(g, (int, np.integer)) and not isinstance(g, bool) and g >= 0 for g in self.rigid):
            raise ValueError(f"Contact needs rigid groups as non-negative integers (got {self.rigid!r})")
        if not 0.0 <= self.friction < np.inf:
            raise ValueError(f"Contact needs a finite friction coefficient >= 0 (got {self.friction})")
        if not 0.0 <= self.mass_cutoff < 1.0:
            raise ValueError(f"Contact needs 0 <= mass_cutoff < 1 (got {self.mass_cutoff})")


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
        twt = np.linalg.norm(wt, axis=1)
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
        stick = held & (friction * dwn >= twt)
        slip = held & ~stick
        new = v[g, at]
        new[stick] = vcm[at[stick]] + (wn - dwn)[stick, None] * n[stick]  # wn - dwn: 0 node by node
        s = np.flatnonzero(slip)
        new[s] -= dwn[s, None] * n[s] + friction * dwn[s, None] * wt[s] / twt[s, None]
        v[g, at] = new
    return contact


def shared_cells(particles, field: str) -> int:
    """The number of cells holding particles of two or more groups of ``fields[field]`` (bodies
    that have not come apart; collective: each particle lives on the rank owning its cell)."""
    pairs = np.unique(np.stack([particles.cells, np.asarray(particles.fields[field])]), axis=1)
    _, groups = np.unique(pairs[0], return_counts=True)
    return particles.comm.allreduce(int(np.count_nonzero(groups > 1)))


def contact_step(solver: ExplicitSolver, dt: float | None, dt_max: float) -> float:
    """One explicit step of ``solver`` with its :class:`Contact` (see the module); returns
    ``dt``."""
    opts = solver.options
    contact = solver.contact
    p = solver.particles
    fld = p.fields
    comm = p.comm
    basis = solver._open_step()
    if contact.field not in fld:
        raise ValueError(f"contact: the particles have no field {contact.field!r} naming their groups")
    group = np.asarray(fld[contact.field])
    bad = comm.allreduce(int(np.count_nonzero((group < 0) | (group != np.round(group)))) if group.ndim == 1 else 1)
    if bad:
        raise ValueError(f"contact: fields[{contact.field!r}] must hold one non-negative integer group per particle")
    group = group.astype(np.int64)
    G = comm.allreduce(int(group.max(initial=-1)) + 1, op=MPI.MAX)
    present = np.zeros(max(G, max(contact.rigid, default=-1) + 1), dtype=np.int64)
    present[:G] = np.bincount(group, minlength=G)
    comm.Allreduce(MPI.IN_PLACE, present, op=MPI.SUM)
    absent = [g for g in contact.rigid if present[g] == 0]
    if absent:
        raise ValueError(f"contact: rigid group(s) {absent} hold no particle (fields[{contact.field!r}] has the groups "
                         f"{np.flatnonzero(present).tolist()})")
    masks = [group == g for g in range(G)]
    rigid = np.isin(np.arange(G), contact.rigid)
    deformable = np.flatnonzero(~rigid)
    m = np.stack([p2g(basis, (p.mass * k)[:, None])[:, 0] for k in masks])
    total = m.sum(axis=0)
    top = comm.allreduce(float(total[: basis.index_map.size_local].max(initial=0.0)), op=MPI.MAX)
    has = m > SUPPORT_TOL * top
    # consistent mass or FMPM: each deformable group's own mass (its masses, zeros elsewhere), with
    # lumped rows at the contact nodes where friction acts (see the module)
    shared = np.count_nonzero(has, axis=0) >= 2 if contact.friction > 0.0 else None
    ops = {} if opts.mass_mode == "lumped" else {g: solver._mass_operator(basis, p.mass * masks[g], lump_dofs=shared)
                                                 for g in deformable}
    dt = solver._time_step(solver._stable_with(list(ops.values())), dt, dt_max)
    d = p.gdim
    eye = np.eye(d)
    grad = np.stack([p2g_gradients(basis, (p.mass * k)[:, None, None] * eye) for k in masks])
    solver._count_terms()
    fext = external_forces(solver.loads, p, solver.t)
    force = np.zeros_like(grad)
    for g in deformable:  # rigid groups take no forces
        k = masks[g]
        force[g] = p2g_gradients(basis, -(p.volume * k)[:, None, None] * fld["sigma"]) + p2g(basis, fext * k[:, None])
    m_has = np.where(has, m, 0.0)
    inv = np.where(has, 1.0 / np.where(has, m, 1.0), 0.0)[:, :, None]
    # per group: a node with a sliver of one body's mass keeps its mapped velocity (a_g = f_g / m_g
    # there is large where the other body's mass keeps the node from counting as weak)
    weak = m <= max(opts.mass_cutoff, contact.mass_cutoff) * top

    # walls that check contact by position see each group's own centre of mass
    moments = None
    centroids = [None] * G
    if solver.needs_positions or contact.gap is not None:  # each group's first mass moment
        moments = np.stack([p2g(basis, (p.mass * k)[:, None] * p.x) for k in masks])
        if solver.needs_positions:
            centroids = [NodalCentres(c, mg) for c, mg in zip(mass_centres(m, moments), m)]

    def constrain(v: npt.NDArray) -> npt.NDArray:
        """Each deformable group's grid conditions, and the ghost values, in place."""
        for g in range(G):
            if not rigid[g]:
                solver._apply_bcs(v[g], centroids[g])
            v[g] = basis.update_ghosts(v[g])
        return v

    def mapped() -> npt.NDArray:
        """Each group's velocity from its particles' momenta (its mass solve)."""
        mom = [p2g(basis, (p.mass * k)[:, None] * fld["v"]) for k in masks]
        return constrain(np.stack([ops[g].solve(mom[g]) if g in ops else mom[g] * inv[g] for g in range(G)]))

    # the mapped velocities are not corrected: the FLIP increment v_new - v_old then carries the
    # whole contact impulse of the step to the particles
    v_old = mapped()
    a = force * inv
    for g, op in ops.items():
        a[g] = solver._accelerations(op, force[g])
    if opts.damping > 0.0:
        a -= opts.damping * v_old
    a[weak] = 0.0
    a[rigid] = 0.0
    v_new = v_old + dt * a
    patches = Patches.of_space(basis.V, index_map=basis.index_map).sums if rigid.any() else None
    correct(m_has, v_new, grad, contact.friction, rigid, moments, contact.gap, dt, patches)
    constrain(v_new)
    # rigid particles keep their velocity and deformation (L = 0) and move with that velocity
    vp = fld["v"].copy()
    vp_grid = fld["v"].copy()
    L = np.zeros((len(p), d, d))
    for g in deformable:  # every particle takes its own group's field
        k = masks[g]
        blended, at_grid, grads = g2p.blend(basis, v_new[g], v_old[g], fld["v"], opts.flip)
        vp[k], vp_grid[k], L[k] = blended[k], at_grid[k], grads[k]
    fld["v"] = vp
    if opts.scheme == "MUSL":
        v_new = mapped()
        for g in deformable:
            k = masks[g]
            at_grid, grads = g2p.velocity_and_gradient(basis, v_new[g])
            vp_grid[k], L[k] = at_grid[k], grads[k]
    solver._update_stress(L, dt)
    if opts.domain == "cpdi2":  # each body's corners move with its own field, rigid ones rigidly
        corner_velocity = np.repeat(fld["v"][:, None, :], fld["corners"].shape[1], axis=1)
        for g in deformable:
            k = masks[g]
            corner_velocity[k] = basis.gather_samples(v_new[g])[k]
        solver._move_corners(basis, corner_velocity, dt)
    else:
        p.x = p.x + dt * (fld["v"] if opts.position == "particle" else vp_grid)
    solver._check_finite()
    solver.t += dt
    solver.step_count += 1
    p.relocate()
    mom = np.einsum("gn,gnd->nd", m_has, v_new)
    solver.grid_velocity = (mom / np.where(total > 0, total, 1.0)[:, None])[: basis.num_dofs_space]
    return dt


def check_options(options) -> None:
    """What :func:`contact_step` supports: USL or MUSL."""
    if options.scheme == "USF":
        raise ValueError("contact supports the schemes USL and MUSL (got USF)")
