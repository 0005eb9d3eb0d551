r"""The particles' side of an implicit step: what a displacement increment of the grid does to
them, and the residual's tangent as per-particle blocks.

The basis (values :math:`N_a(x_p)`, gradients :math:`\nabla N_a(x_p)`, averaged over the
particle domain where there is one) is tabulated once, where the particles sit at the step's
start, and stays fixed while Newton iterates (:mod:`fempm.implicit.nominal`). For an increment
:math:`\Delta u` of the grid,

.. math::
    G_p = \sum_a \Delta u_a \otimes \nabla N_a(x_p), \qquad
    f^{int}_a = \sum_p V_p^n P_p \nabla N_a(x_p), \qquad
    K_{a i, b k} = \sum_p V_p^n\, \partial_m N_a\, \mathbb{A}_{p, imkl}\, \partial_l N_b
    + c \sum_p M_p\, N_a N_b\, \delta_{ik},

the last term the inertia of Newmark's method (:math:`c = 1/(\beta \Delta t^2)`), with the
consistent mass or, lumped, :math:`c\, \delta_{ab} \sum_p M_p N_a`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from fempm.implicit.nominal import nominal_stress
from fempm.kernels.implicit import increment_gradients
from fempm.kernels.implicit_blocks import cell_tangent_blocks, tangent_blocks
from fempm.materials.tangent import stress_after, tangent_fixed_in_step, tangent_of
from fempm.particles.particle_set import Particles
from fempm.stepping.laws import every, law_state, material_groups
from fempm.transfer.basis import ParticleBasis
from fempm.transfer.mapping import p2g, p2g_gradients

__all__ = ["IncrementOperator"]


class IncrementOperator:
    """The increment's action on the particles of a step (see the module).

    Args:
        basis: The basis at the particles at the step's start, with gradients.
        particles: The particles (their state at the step's start is read, not changed).
        materials: The laws, one per body index.
        finite_difference: Take the laws' tangents by central differences
            (:func:`fempm.materials.tangent.finite_difference_tangent`) instead of their own.
        dt: The step's length, given to the laws with the increments (a rate-dependent law's
            stress depends on it: :func:`fempm.materials.tangent.stress_after`).
    """

    def __init__(self, basis: ParticleBasis, particles: Particles, materials: Sequence,
                 finite_difference: bool = False, dt: float = 1.0):
        f = particles.fields
        self.basis = basis
        self.d = particles.gdim
        self.volume = particles.volume.copy()
        self.mass = particles.mass
        self.rho = particles.mass / particles.volume
        self.F, self.sigma = f["F"], f["sigma"]
        n = len(self.volume)  # a law of every particle reads them through a slice, not copies
        self.groups = [(mat, every(idx, n), law_state(mat, f, idx))
                       for mat, idx in material_groups(f, materials)]
        self.finite_difference = finite_difference
        self.dt = dt
        self._last: tuple[npt.NDArray, npt.NDArray] | None = None  # (G, sigma) of the last call
        self._fixed: npt.NDArray | None = None  # the laws' tangents where they hold for the step
        self._groups: tuple[npt.NDArray, npt.NDArray, npt.NDArray] | None = None  # (dof_groups)

    def gradients(self, du: npt.NDArray) -> npt.NDArray:
        r""":math:`G_p = \sum_a \Delta u_a \otimes \nabla N_a(x_p)` (n, d, d) of an increment ``du``
        (owned + ghost dofs, d)."""
        b = self.basis
        return increment_gradients(np.ascontiguousarray(du), b.dofs, b.gradients)

    def stresses(self, G: npt.NDArray, tangent: bool) -> tuple[npt.NDArray, npt.NDArray | None]:
        r"""The nominal stresses :math:`P_p` (n, d, d) after the increments of gradients ``G``,
        and with ``tangent`` their tangents :math:`\mathbb{A}_p` (n, d, d, d, d) (else None). The
        Cauchy stresses of the last call are kept: Newton asks for the tangent where it has just
        evaluated the residual, and the laws' stress update is not repeated there."""
        known = self._last is not None and np.array_equal(self._last[0], G)
        sigma = self._last[1] if known else self._per_law(
            lambda mat, idx, state: stress_after(mat, self.F[idx], G[idx], self.sigma[idx], self.rho[idx], state,
                                                 self.dt)[0])
        D = self._tangents(G) if tangent else None
        self._last = (G, sigma)
        return nominal_stress(sigma, D, G)

    def _tangents(self, G: npt.NDArray) -> npt.NDArray:
        r"""The laws' tangents :math:`\mathbb{D}_p` at the increments ``G``, kept for the step where
        every law's is the same at every increment (:func:`fempm.materials.tangent.tangent_fixed_in_step`)."""
        if self._fixed is not None:
            return self._fixed
        D = self._per_law(lambda mat, idx, state: tangent_of(
            mat, self.F[idx], G[idx], self.sigma[idx], self.rho[idx], state, finite_difference=self.finite_difference,
            dt=self.dt))
        if not self.finite_difference and all(tangent_fixed_in_step(mat) for mat, _, _ in self.groups):
            self._fixed = D
        return D

    def _per_law(self, value) -> npt.NDArray:
        """``value(law, idx, state)`` of every law's particles, in one array (n, ...): a law of
        every particle gives it whole (no copy)."""
        if len(self.groups) == 1 and isinstance(self.groups[0][1], slice):
            return value(*self.groups[0])
        out = None
        for mat, idx, state in self.groups:
            part = value(mat, idx, state)
            if out is None:
                out = np.empty((len(self.volume),) + part.shape[1:])
            out[idx] = part
        return out

    def law_gradients(self, G: npt.NDArray) -> npt.NDArray:
        """The increments the laws see for the increments ``G``: ``G`` itself (F-bar averages
        them, :class:`fempm.implicit.fbar.FBarIncrementOperator`)."""
        return G

    def forces(self, G: npt.NDArray) -> npt.NDArray:
        r"""The stresses :math:`P_p` (n, d, d) whose scatter is the internal force of the increments ``G``."""
        return self.stresses(G, tangent=False)[0]

    def tangents(self, G: npt.NDArray) -> tuple[npt.NDArray, tuple | None]:
        r"""The particles' tangent blocks :math:`\mathbb{A}_p` (n, d, d, d, d) at the increments
        ``G``, and what couples particles beyond them (None here)."""
        return self.stresses(G, tangent=True)[1], None

    def internal_force(self, P: npt.NDArray) -> npt.NDArray:
        r""":math:`f^{int}_a = \sum_p V_p^n P_p \nabla N_a` (owned + ghost dofs, d), summed over ranks."""
        return p2g_gradients(self.basis, self.volume[:, None, None] * P)

    def nodal(self, values: npt.NDArray) -> npt.NDArray:
        r""":math:`\sum_p N_a(x_p)\, w_p` of per-particle ``values`` (n, k), summed over ranks."""
        return p2g(self.basis, values)

    def support(self) -> npt.NDArray:
        r"""How strongly the particles reach each dof, :math:`\sum_p M_p N_a(x_p)^2` (owned +
        ghost dofs), summed over ranks: the consistent mass's diagonal, positive wherever a
        particle sees the dof, whatever the sign of the basis (P2 Lagrange)."""
        return p2g(self.basis, self.mass[:, None], values=self.basis.values**2)[:, 0]

    def mass_times(self, a: npt.NDArray, consistent: bool, lumped: npt.NDArray) -> npt.NDArray:
        r""":math:`M a` of nodal vectors ``a`` (owned + ghost dofs, d): the consistent mass
        :math:`\sum_p M_p N_a(x_p) \sum_b N_b(x_p) a_b`, else the ``lumped`` masses times ``a``."""
        if consistent:
            return self.nodal(self.mass[:, None] * self.basis.gather(a))
        return lumped[:, None] * a

    def dof_groups(self) -> tuple[npt.NDArray, npt.NDArray, npt.NDArray]:
        """(the dofs of each group (groups, k), each particle's group (n,), a particle of each group
        (groups,)): point particles in a cell share its block of the tangent, so that its COO
        entries are a block per occupied cell, not per particle (a quarter of the entries with 4
        particles a cell; particle domains, whose dofs are their own: a group per particle)."""
        b = self.basis
        if self._groups is None and b.cells is None:  # particle domains: a block per particle
            every_particle = np.arange(len(b.dofs))
            self._groups = (b.dofs, every_particle, every_particle)
        elif self._groups is None:  # point particles: a cell's particles have its dofs
            _, first, slot = np.unique(b.cells, return_index=True, return_inverse=True)
            self._groups = (b.dofs[first], slot.ravel(), first)
        return self._groups

    def pattern(self) -> tuple[npt.NDArray, npt.NDArray]:
        """(rows, columns) of the tangent's entries in local scalar indices (dof d + component):
        each block over a group's dofs (:meth:`dof_groups`, :meth:`tangent_values`' order), then
        the diagonal of every local dof (zeros where no particle reaches: their rows are held)."""
        d = self.d
        dofs = self.dof_groups()[0]
        idx = (dofs[:, :, None] * d + np.arange(d)).reshape(len(dofs), -1)  # (n, k d)
        m = idx.shape[1]
        diagonal = np.arange(self.basis.num_dofs_local * d)
        rows = np.concatenate([np.broadcast_to(idx[:, :, None], (len(idx), m, m)).ravel(), diagonal])
        cols = np.concatenate([np.broadcast_to(idx[:, None, :], (len(idx), m, m)).ravel(), diagonal])
        return rows, cols

    def tangent_values(self, A: npt.NDArray, mass_factor: float, consistent: bool) -> npt.NDArray:
        r"""The entries of :meth:`pattern`: each particle's
        :math:`V_p^n \nabla N_a \cdot \mathbb{A}_p \cdot \nabla N_b` plus ``mass_factor`` times
        its mass block (consistent, or lumped on the block's diagonal), summed over its group of
        :meth:`dof_groups`, then zeros (one compiled pass, :func:`fempm.kernels.implicit.tangent_blocks`;
        where a cell's particles share its gradients, degree 1 on affine simplices, their
        :math:`V_p \mathbb{A}_p` and mass factors summed first, :func:`~fempm.kernels.implicit.cell_tangent_blocks`)."""
        b = self.basis
        dofs, slot, first = self.dof_groups()
        if b.constant_gradients:  # a cell's particles share its gradients: its sums, then one block
            return cell_tangent_blocks(b.gradients, b.values, A, self.volume, self.mass, mass_factor, consistent,
                                       b.num_dofs_local * self.d, slot, first)
        return tangent_blocks(b.gradients, b.values, A, self.volume, self.mass, mass_factor, consistent,
                              b.num_dofs_local * self.d, slot, len(dofs))
