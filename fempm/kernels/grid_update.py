r"""The lumped mass's grid update, compiled passes over the dofs (the explicit step of
:class:`fempm.stepping.lumped.PointGrid` and :class:`fempm.stepping.lumped_mass.LumpedNodalMass`):
:math:`v_i = (m v)_i / m_i` on free dofs with :math:`m_i > \epsilon_a`, 0 elsewhere;
:math:`a_i = f_i / m_i - c\, v_i` (0 on constrained dofs and where :math:`m_i \le \epsilon_w`),
:math:`v_i^+ = v_i + \Delta t\, a_i`.
"""

from __future__ import annotations

from fempm.kernels.shape import AVAILABLE

__all__ = ["grid_advance", "grid_update", "grid_velocity"]

if AVAILABLE:
    from numba import njit

    @njit(cache=True, error_model="numpy")
    def grid_velocity(mass, mom, cv, free, active_min, v):  # pragma: no cover
        """``v`` (ndofs, d) = momentum ``mom[:, cv:cv+d]`` / ``mass[:, 0]`` on free dofs with
        mass above ``active_min``, else 0."""
        nd, d = v.shape
        for i in range(nd):
            m = mass[i, 0]
            for j in range(d):
                v[i, j] = mom[i, cv + j] / m if (m > active_min and free[i, j]) else 0.0

    @njit(cache=True, error_model="numpy")
    def grid_advance(mass, force, free, active_min, weak_max, dt, damping, v_old, v_new):  # pragma: no cover
        """``v_new = v_old + dt a`` with ``a = force / mass - damping v_old`` (0 on constrained or
        inactive dofs and where the mass is at most ``weak_max``)."""
        nd, d = v_old.shape
        for i in range(nd):
            m = mass[i, 0]
            for j in range(d):
                a = force[i, j] / m if (m > active_min and free[i, j]) else 0.0
                a -= damping * v_old[i, j]
                if m <= weak_max:
                    a = 0.0
                v_new[i, j] = v_old[i, j] + dt * a

    @njit(cache=True, error_model="numpy")
    def grid_update(nodal, cv, cf, free, active_min, weak_max, dt, damping, v_old, v_new):  # pragma: no cover
        """:func:`grid_velocity` then :func:`grid_advance` in one pass over the dofs, from one
        nodal array with the mass in column 0, the momenta from column ``cv``, the forces from
        ``cf`` (one division per dof: the momenta and forces are multiplied by :math:`1/m_i`)."""
        nd, d = v_old.shape
        for i in range(nd):
            m = nodal[i, 0]
            active = m > active_min
            inv = 1.0 / m if active else 0.0
            weak = m <= weak_max
            for j in range(d):
                on = active and free[i, j]
                vo = nodal[i, cv + j] * inv if on else 0.0
                a = nodal[i, cf + j] * inv if on else 0.0
                a -= damping * vo
                if weak:
                    a = 0.0
                v_old[i, j] = vo
                v_new[i, j] = vo + dt * a
