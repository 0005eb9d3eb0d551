r"""The reactions of the grid conditions: the momentum the supports and walls take in a step.

A fixed end, a slip or frictional wall and an absorbing dashpot change the bodies' momentum as
legitimately as a load does; the run's momentum balance
(:class:`fempm.stepping.health.HealthMonitor`, ``momentum_drift``) counts what they took, as it
counts the colliders' impulses. In a step the particles' momentum changes by

.. math::
    \Delta P = \sum_i \big[m_i (v_i^{+} - v_i) + (1-\alpha)(m_i v_i - p_i)\big]

(:math:`\alpha` the FLIP fraction, :math:`m_i = \sum_p M_p N_{ip}` the lumped masses, signed
for a degree-2 Lagrange basis, :math:`p_i` the mapped momenta, :math:`v_i` and :math:`v_i^+`
the grid velocities before and after the update, both constrained), while the nodal forces
:math:`f_i` (internal ones summing to zero) and the mass-proportional damping
:math:`-c\, m_i v_i` impart :math:`\Delta t \sum_i (f_i - c\, m_i v_i)`. The residual of
node :math:`i`,

.. math::
    r_i = \Delta t\,(f_i - c\, m_i v_i) - m_i (v_i^{+} - v_i) + (1-\alpha)(p_i - m_i v_i),

(the damping only where the update applies accelerations: not at the nodes too light for it,
``mass_cutoff``) is what the conditions (and colliders) took there. With the lumped mass it vanishes at every
node they leave alone, so the reaction is the sum over the nodes of the conditions
(:attr:`fempm.boundary.conditions.GridConditions.held_dofs`); with a mass that couples the
dofs (consistent, FMPM(k)) the free rows of the solve balance only together, so the sum runs
over every node (the mass solve's tolerance then counts as a reaction). The colliders' own
impulses at those nodes (:attr:`fempm.colliders.grid.ColliderContact.nodal_impulse`) are
taken out: they are counted as theirs. The damping's own impulse,
:math:`-c\, \Delta t \sum_i m_i v_i`, is a known external action too (:func:`damping_impulse`).
"""

from __future__ import annotations

import numpy.typing as npt

__all__ = ["damping_impulse", "nodal_reaction"]


def nodal_reaction(mass: npt.NDArray, momentum: npt.NDArray, force: npt.NDArray, v_old: npt.NDArray,
                   v_new: npt.NDArray, moving: npt.NDArray, dt: float, flip: float, damping: float,
                   rows: npt.NDArray) -> npt.NDArray:
    r""":math:`\sum_{i \in \text{rows}} r_i` (see the module) on this rank.

    Args:
        mass: the lumped nodal masses (dofs,).
        momentum: the mapped nodal momenta (dofs, d), before any condition.
        force: the nodal forces of the update (dofs, d).
        v_old: the constrained grid velocity mapped from the particles (dofs, d).
        v_new: the constrained updated grid velocity (dofs, d).
        moving: where the update applies accelerations (dofs,) bool (the damping acts there).
        dt: the step.
        flip: the FLIP fraction :math:`\alpha` of the blend.
        damping: the mass-proportional damping rate :math:`c`.
        rows: the owned dofs summed over (indices).

    Returns:
        (d,): the momentum the conditions took at those dofs in the step (not summed over ranks).
    """
    m = mass[rows, None]
    vo = v_old[rows]
    damped = damping * moving[rows, None] * m * vo
    r = dt * (force[rows] - damped) - m * (v_new[rows] - vo) + (1.0 - flip) * (momentum[rows] - m * vo)
    return r.sum(axis=0)


def damping_impulse(mass: npt.NDArray, v_old: npt.NDArray, moving: npt.NDArray, dt: float, damping: float,
                    num_owned: int) -> npt.NDArray:
    r"""The impulse of the mass-proportional damping in a step, :math:`-c\, \Delta t \sum_i m_i v_i`
    over the owned dofs the update moves (arguments as :func:`nodal_reaction`; not summed over
    ranks)."""
    own = moving[:num_owned]
    return -damping * dt * (mass[:num_owned][own] @ v_old[:num_owned][own])
