r"""The grid update of multi-field contact in compiled passes over the dofs
(:class:`fempm.stepping.contact_points.ContactPointGrid` drives them; the numpy stages of
:class:`fempm.stepping.contact.ContactGrid` and :func:`fempm.stepping.contact.correct` are
their reference).

The nodal array holds a block of ``stride`` columns per group g, :math:`[m^g \mid m^g v^g \mid
f^g \mid \nabla m^g]`. :func:`grid_update`, node by node: each group's velocity
:math:`v^g = (m v)^g / m^g` (0 where :math:`m^g \le \epsilon_a` and on constrained components),
:math:`v^{g+} = v^g + \Delta t\,(f^g / m^g - c\, v^g)` (no update where :math:`m^g \le
\epsilon_w`), then at a contact node (two or more groups with mass) the correction of
:mod:`fempm.stepping.contact` against the centre-of-mass velocity (normals from the mass
gradients, Coulomb friction, and with a gap the position check), then the constrained
components set to 0; with the groups' velocities and accelerations given (the consistent mass's
solves) the same update from them. :func:`group_velocity`: the first part alone (MUSL's re-mapped momenta);
:func:`centre_of_mass`: :math:`\sum_g m^g v^g / \sum_g m^g` over the groups with mass.
"""

from __future__ import annotations

import functools

import numpy as np

from fempm.kernels.choice import INLINE
from fempm.kernels.shape import AVAILABLE

__all__ = ["centre_of_mass", "grid_update", "group_velocity", "largest_total"]

if AVAILABLE:
    from numba import njit

    @njit(inline=INLINE)
    def _correct_group(nodal, stride, i, g, d, active_min, node, scratch, law, moments, tiny,
                       v_new):  # pragma: no cover - compiled
        """Group g's correction at contact node i (:func:`fempm.stepping.contact.correct`):
        ``node`` = the node's (total mass, centre-of-mass velocity, mass gradient, moment sums),
        ``scratch`` = (normal, w) arrays, ``law`` = (friction, gap, dt)."""
        total, vcm, all_grad, moment_sum = node
        normal, w = scratch
        friction, gap, dt = law
        o = g * stride
        m = nodal[i, o]
        if not m > active_min:
            return
        size = 0.0
        for j in range(d):
            normal[j] = 2.0 * nodal[i, o + 1 + 2 * d + j] - all_grad[j]  # out of group g
            size += normal[j] * normal[j]
        if not size > 0.0:
            return
        size = np.sqrt(size)
        wn = 0.0
        for j in range(d):
            normal[j] /= size
            w[j] = v_new[i, g * d + j] - vcm[j]
            wn += w[j] * normal[j]
        if not wn > 0.0:  # separating: left free
            return
        if gap > 0.0:  # touching: the others' centre of mass within gap ahead of its own
            others = max(total - m, tiny)
            ahead = 0.0
            for j in range(d):
                ahead += ((moment_sum[j] - moments[i, g * d + j]) / others - moments[i, g * d + j] / m) * normal[j]
            if not gap - (ahead - dt * wn * total / others) > 0.0:
                return
        speed = 0.0
        for j in range(d):
            w[j] -= wn * normal[j]  # the tangential part
            speed += w[j] * w[j]
        speed = np.sqrt(speed)
        keep = max(0.0, 1.0 - friction * wn / speed) if speed > 0.0 else 0.0
        for j in range(d):
            v_new[i, g * d + j] = vcm[j] + w[j] * keep


def grid_update(nodal, stride, free, active_min, weak_max, dt, damping, friction, gap, moments, v_old, v_new, *,
                accelerations=None):
    """See the module: ``v_old`` and ``v_new`` (dofs, G d); ``gap`` > 0 with the groups' first
    mass moments ``moments`` (dofs, G d), else ``gap`` <= 0; ``accelerations`` (dofs, G d): the
    groups' given accelerations, and ``v_old`` their given velocities (else ``v_old`` is
    written from the momenta and the accelerations are :math:`f^g / m^g`). Returns the number
    of contact nodes."""
    given = accelerations is not None
    a = accelerations if given else np.zeros((0, 0))
    return _grid_update(free.shape[1], nodal.shape[1] // stride, given)(
        nodal, stride, free, active_min, weak_max, dt, damping, friction, gap, moments, (v_old, v_new, a))


@functools.cache
def _grid_update(d: int, G: int, given: bool = False):
    """:func:`grid_update` compiled for d components and G groups (its loops unroll); ``given``:
    the velocities and accelerations given."""

    @njit(cache=True, error_model="numpy")
    def kernel(nodal, stride, free, active_min, weak_max, dt, damping, friction, gap, moments,
               velocities):  # pragma: no cover - compiled
        v_old, v_new, accelerations = velocities
        n = free.shape[0]
        vcm = np.empty(d)
        all_grad = np.empty(d)
        moment_sum = np.empty(d)
        normal = np.empty(d)
        w = np.empty(d)
        tiny = np.finfo(np.float64).tiny
        contacts = 0
        for i in range(n):
            count = 0
            total = 0.0
            for j in range(d):
                vcm[j] = 0.0
                all_grad[j] = 0.0
                moment_sum[j] = 0.0
            for g in range(G):
                o = g * stride
                m = nodal[i, o]
                has = m > active_min
                inv = 1.0 / m if has else 0.0
                weak = m <= weak_max
                for j in range(d):
                    if given:
                        vo = v_old[i, g * d + j]
                        a = 0.0 if weak else accelerations[i, g * d + j] - damping * vo
                    else:
                        vo = nodal[i, o + 1 + j] * inv if free[i, j] else 0.0
                        a = 0.0 if weak else nodal[i, o + 1 + d + j] * inv - damping * vo
                        v_old[i, g * d + j] = vo
                    v_new[i, g * d + j] = vo + dt * a
                    all_grad[j] += nodal[i, o + 1 + 2 * d + j]
                    if gap > 0.0:
                        moment_sum[j] += moments[i, g * d + j]
                if has:
                    count += 1
                    total += m
                    for j in range(d):
                        vcm[j] += m * v_new[i, g * d + j]
            if count >= 2:
                contacts += 1
                for j in range(d):
                    vcm[j] /= total
                for g in range(G):
                    _correct_group(nodal, stride, i, g, d, active_min, (total, vcm, all_grad, moment_sum),
                                   (normal, w), (friction, gap, dt), moments, tiny, v_new)
            for g in range(G):
                for j in range(d):
                    if not free[i, j]:
                        v_new[i, g * d + j] = 0.0
        return contacts

    return kernel


def group_velocity(mass, stride, mom, mom_stride, cv, free, active_min, v):
    """``v[:, g d + j]`` = ``mom[:, g mom_stride + cv + j]`` / ``mass[:, g stride]`` on the free
    components where that mass is above ``active_min``, else 0."""
    d = free.shape[1]
    _group_velocity(d, v.shape[1] // d)(mass, stride, mom, mom_stride, cv, free, active_min, v)


@functools.cache
def _group_velocity(d: int, G: int):
    """:func:`group_velocity` compiled for d components and G groups."""

    @njit(cache=True, error_model="numpy")
    def kernel(mass, stride, mom, mom_stride, cv, free, active_min, v):  # pragma: no cover - compiled
        for i in range(v.shape[0]):
            for g in range(G):
                m = mass[i, g * stride]
                inv = 1.0 / m if m > active_min else 0.0
                for j in range(d):
                    v[i, g * d + j] = mom[i, g * mom_stride + cv + j] * inv if free[i, j] else 0.0

    return kernel


def centre_of_mass(mass, stride, active_min, v, out):
    r"""``out`` (dofs, d) = :math:`\sum_g m^g v^g / \sum_g m^g`, the numerator over the groups with
    mass above ``active_min`` (0 where none has), masses ``mass[:, g stride]``, ``v`` (dofs, G d)."""
    d = out.shape[1]
    _centre_of_mass(d, v.shape[1] // d)(mass, stride, active_min, v, out)


@functools.cache
def _centre_of_mass(d: int, G: int):
    """:func:`centre_of_mass` compiled for d components and G groups."""

    @njit(cache=True, error_model="numpy")
    def kernel(mass, stride, active_min, v, out):  # pragma: no cover - compiled
        for i in range(v.shape[0]):
            total = 0.0
            for j in range(d):
                out[i, j] = 0.0
            for g in range(G):
                m = mass[i, g * stride]
                total += m
                if m > active_min:
                    for j in range(d):
                        out[i, j] += m * v[i, g * d + j]
            inv = 1.0 / total if total > 0.0 else 1.0
            for j in range(d):
                out[i, j] *= inv

    return kernel


@functools.cache
def _largest_total(G: int):
    """:func:`largest_total` compiled for G groups."""

    @njit(cache=True, error_model="numpy")
    def kernel(mass, stride, n):  # pragma: no cover - compiled
        top = 0.0
        for i in range(n):
            total = 0.0
            for g in range(G):
                total += mass[i, g * stride]
            top = max(top, total)
        return top

    return kernel


def largest_total(mass, stride: int, G: int, n: int) -> float:
    r""":math:`\max_{i < n} \sum_g m_i^g` (0 if n = 0), masses ``mass[:, g stride]``."""
    return _largest_total(G)(mass, stride, n)
