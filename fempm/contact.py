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
round-off. The correction is applied to the updated velocities (and, with MUSL, to the
re-mapped ones), not to the mapped ones: the FLIP increment :math:`v^g_{new} - v^g_{old}` then
carries the whole contact impulse to the particles, and each particle takes its own group's
field in G2P.
Lumped mass, every particle domain but CPDI2, USL and MUSL, any number of ranks (the nodal
sums are summed over ranks as in the single-field step, and the correction is node-local).

A node where a group has less than ``mass_cutoff`` (default 1 %) of the largest nodal mass
gives that group no force update there (it keeps the mapped velocity): in a single field such
a node shares the other body's mass and :math:`f/m` stays bounded; per group it does not, and
on the colliding disks USL at CFL 0.4 blows up with the single field's cut-off (1e-9) and is
stable with 1 %. With MUSL the re-mapped velocities are not corrected again (a correction the
particles' momenta do not carry adds energy); MUSL with contact still gains 15-17 % energy on
the disks at CFL 0.4 and none at CFL 0.1, where USL loses 12 %.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.loads import external_forces
from fempm.transfer import SUPPORT_TOL, p2g, p2g_gradients

if TYPE_CHECKING:
    from fempm.stepping import ExplicitSolver


@dataclass(frozen=True)
class Contact:
    """Multi-velocity-field contact with Coulomb ``friction`` between the particle groups named
    by ``fields[field]`` (integers 0, 1, ...; default the material index ``body``)."""

    friction: float = 0.0
    field: str = "body"
    mass_cutoff: float = 1e-2

    def __post_init__(self):
        if not 0.0 <= self.friction < np.inf:
            raise ValueError(f"Contact needs a finite friction coefficient >= 0 (got {self.friction})")
        if not 0.0 <= self.mass_cutoff < 1.0:
            raise ValueError(f"Contact needs 0 <= mass_cutoff < 1 (got {self.mass_cutoff})")


def correct(m: npt.NDArray, v: npt.NDArray, grad: npt.NDArray, friction: float) -> npt.NDArray[np.bool_]:
    r"""The contact correction of the module, in place: group masses ``m`` (G, n), velocities
    ``v`` (G, n, d) and mass gradients ``grad`` (G, n, d) at n nodes; returns which nodes are
    contact nodes (two or more groups with mass)."""
    present = m > 0.0
    contact = np.count_nonzero(present, axis=0) >= 2
    if not contact.any():
        return contact
    total = m.sum(axis=0)
    vcm = np.einsum("gn,gnd->nd", m, v) / np.where(total > 0, total, 1.0)[:, None]
    all_grad = grad.sum(axis=0)
    for g in range(len(m)):  # a loop over the groups (a few), not over nodes
        normal = 2.0 * grad[g] - all_grad  # grad m_g - sum of the others: out of group g
        size = np.linalg.norm(normal, axis=1)
        at = np.flatnonzero(contact & present[g] & (size > 0.0))
        n = normal[at] / size[at, None]
        w = v[g, at] - vcm[at]
        wn = np.einsum("nd,nd->n", w, n)
        wt = w - wn[:, None] * n
        twt = np.linalg.norm(wt, axis=1)
        approach = wn > 0.0
        stick = approach & (friction * wn >= twt)
        slip = approach & ~stick
        new = v[g, at]
        new[stick] = vcm[at[stick]]
        s = np.flatnonzero(slip)
        new[s] -= wn[s, None] * n[s] + friction * wn[s, None] * wt[s] / twt[s, None]
        v[g, at] = new
    return contact


def contact_step(solver: ExplicitSolver, dt: float | None, dt_max: float) -> float:
    """One explicit step of ``solver`` with its :class:`Contact` (see the module); returns
    ``dt``."""
    opts = solver.options
    contact = solver.contact
    p = solver.particles
    fld = p.fields
    comm = p.comm
    basis = solver._open_step()
    dt = solver._time_step(solver.stable_dt(), dt, dt_max)
    if contact.field not in fld:
        raise ValueError(f"contact: the particles have no field {contact.field!r} naming their groups")
    group = np.asarray(fld[contact.field])
    bad = comm.allreduce(int(np.count_nonzero((group < 0) | (group != np.round(group)))) if group.ndim == 1 else 1)
    if bad:
        raise ValueError(f"contact: fields[{contact.field!r}] must hold one non-negative integer group per particle")
    group = group.astype(np.int64)
    G = comm.allreduce(int(group.max(initial=-1)) + 1, op=MPI.MAX)
    masks = [group == g for g in range(G)]
    d = p.gdim
    eye = np.eye(d)
    m = np.stack([p2g(basis, (p.mass * k)[:, None])[:, 0] for k in masks])
    grad = np.stack([p2g_gradients(basis, (p.mass * k)[:, None, None] * eye) for k in masks])
    solver._count_terms()
    fext = external_forces(solver.loads, p, solver.t)
    force = np.stack([p2g_gradients(basis, -(p.volume * k)[:, None, None] * fld["sigma"]) + p2g(basis, fext * k[:, None])
                      for k in masks])
    total = m.sum(axis=0)
    top = comm.allreduce(float(total[: basis.index_map.size_local].max(initial=0.0)), op=MPI.MAX)
    has = m > SUPPORT_TOL * top
    m_has = np.where(has, m, 0.0)
    inv = np.where(has, 1.0 / np.where(has, m, 1.0), 0.0)[:, :, None]
    # per group: a node with a sliver of one body's mass keeps its mapped velocity (a_g = f_g / m_g
    # there is large where the other body's mass keeps the node from counting as weak)
    weak = m <= max(opts.mass_cutoff, contact.mass_cutoff) * top

    def constrain(v: npt.NDArray) -> npt.NDArray:
        """Each group's grid conditions and ghost values, in place."""
        for g in range(G):
            solver._apply_bcs(v[g])
            v[g] = basis.update_ghosts(v[g])
        return v

    def mapped() -> npt.NDArray:
        """Each group's velocity from its particles' momenta."""
        return constrain(np.stack([p2g(basis, (p.mass * k)[:, None] * fld["v"]) for k in masks]) * inv)

    # the mapped velocities are not corrected: the FLIP increment v_new - v_old then carries the
    # whole contact impulse of the step to the particles
    v_old = mapped()
    a = force * inv
    if opts.damping > 0.0:
        a -= opts.damping * v_old
    a[weak] = 0.0
    v_new = v_old + dt * a
    correct(m_has, v_new, grad, contact.friction)
    constrain(v_new)
    vp = np.empty_like(fld["v"])
    vp_grid = np.empty_like(fld["v"])
    L = np.empty((len(p), d, d))
    for g, k in enumerate(masks):  # every particle takes its own group's field
        blended, at_grid, grads = solver._g2p(basis, v_new[g], v_old[g], fld["v"], opts.flip)
        vp[k], vp_grid[k], L[k] = blended[k], at_grid[k], grads[k]
    fld["v"] = vp
    if opts.scheme == "MUSL":
        v_new = mapped()
        for g, k in enumerate(masks):
            at_grid, grads = solver._interpolate(basis, v_new[g])
            vp_grid[k], L[k] = at_grid[k], grads[k]
    solver._update_stress(L, dt)
    p.x = p.x + dt * (fld["v"] if opts.position == "particle" else vp_grid)
    solver._check_finite()
    solver.t += dt
    solver.step_count += 1
    p.relocate()
    mom = np.einsum("gn,gnd->nd", m_has, v_new)
    solver.grid_velocity = (mom / np.where(total > 0, total, 1.0)[:, None])[: basis.num_dofs_space]
    return dt


def check_options(options) -> None:
    """What :func:`contact_step` supports: lumped mass, USL or MUSL, any domain but CPDI2."""
    if options.mass_mode != "lumped":
        raise ValueError(f"contact needs lumped mass (got mass={options.mass!r})")
    if options.scheme == "USF":
        raise ValueError("contact supports the schemes USL and MUSL (got USF)")
    if options.domain == "cpdi2":
        raise ValueError("contact does not support domain='cpdi2' (its corners move with one grid field)")
