r"""The reaction of the grid conditions in a step, a compiled pass over the dofs: the sum over
the given rows of the residual

.. math::
    r_i = \Delta t\,(f_i - c\, m_i v_i) - m_i (v_i^{+} - v_i) + (1-\alpha)(p_i - m_i v_i)

(the damping only where the update moves the node) of :mod:`fempm.stepping.reactions`, whose
:func:`~fempm.stepping.reactions.nodal_reaction` is the numpy reference. With a mass that
couples the dofs the rows are every owned dof, every step: in numpy the temporaries of that sum
took a fifth of a consistent-mass step.
"""

from __future__ import annotations

from fempm.kernels.shape import AVAILABLE

__all__ = ["AVAILABLE", "reaction_sum"]

if AVAILABLE:
    from numba import njit

    @njit(cache=True, error_model="numpy")
    def reaction_sum(fields, dt, flip, damping, rows, out):  # pragma: no cover - compiled
        r"""``out`` (d,) <- :math:`\sum_{i \in \text{rows}} r_i` of one velocity field, ``fields`` =
        (lumped masses (dofs,), mapped momenta, forces, ``v_old``, ``v_new`` (dofs, d), where the
        update moves the node (dofs,) bool) (the arguments of
        :func:`fempm.stepping.reactions.nodal_reaction`)."""
        mass, momentum, force, v_old, v_new, moving = fields
        d = v_old.shape[1]
        for j in range(d):
            out[j] = 0.0
        keep = 1.0 - flip
        for k in range(len(rows)):
            i = rows[k]
            m = mass[i]
            c = damping * m if moving[i] else 0.0
            for j in range(d):
                vo = v_old[i, j]
                out[j] += dt * (force[i, j] - c * vo) - m * (v_new[i, j] - vo) + keep * (momentum[i, j] - m * vo)
