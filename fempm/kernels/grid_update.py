r"""The lumped mass's grid update, compiled passes over the dofs (the explicit step of
:class:`fempm.stepping.lumped.PointGrid` and :class:`fempm.stepping.lumped_mass.LumpedNodalMass`):
:math:`v_i = (m v)_i / m_i` on free dofs with :math:`m_i > \epsilon_a`, 0 elsewhere;
:math:`a_i = f_i / m_i - c\, v_i` (0 on constrained dofs and where :math:`m_i \le \epsilon_w`),
:math:`v_i^+ = v_i + \Delta t\, a_i`; and the grid velocity of the affine transfers' weak-node
cutoff (:func:`affine_cutoff_velocity`, reference :func:`fempm.transfer.affine.affine_velocity`).
"""

from __future__ import annotations

from fempm.kernels.shape import AVAILABLE

__all__ = ["affine_cutoff_velocity", "grid_advance", "grid_update", "grid_velocity"]

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

    @njit(cache=True, error_model="numpy")
    def affine_cutoff_velocity(v_new, v_old, mass, weak, v, flags):  # pragma: no cover
        r"""The grid velocity G2P takes the affine matrices from (as
        :func:`fempm.transfer.affine.affine_velocity`): ``v`` = :math:`v_i + w_i (v_i^+ - v_i)`,
        :math:`w_i = m_i / m_w`, and ``flags[i]`` = 1 on the dofs with :math:`0 < m_i < m_w`
        (``weak``, over all of ``mass``); elsewhere ``flags`` 0 and ``v`` = :math:`v_i^+`.
        Returns the number of flagged dofs of ``v``."""
        nd, d = v_new.shape
        count = 0
        for i in range(len(flags)):
            m = mass[i]
            on = 0.0 < m < weak
            flags[i] = 1 if on else 0
            if i < nd:
                for j in range(d):
                    v[i, j] = v_old[i, j] + (m / weak) * (v_new[i, j] - v_old[i, j]) if on else v_new[i, j]
                count += 1 if on else 0
        return count
