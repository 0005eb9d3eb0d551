"""The compiled grid masses of :class:`fempm.stepping.lumped.PointGrid`: the lumped one
(:class:`LumpedNodalMass`) and the mass model -> grid mass table (:data:`NODAL_MASSES`)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from fempm.kernels.grid_update import grid_advance, grid_velocity
from fempm.stepping.consistent import ConsistentNodalMass
from fempm.stepping.fmpm_mass import FMPMNodalMass
from fempm.stepping.nodal import NodalMass
from fempm.transfer.mass_models import FMPM, Consistent, Lumped

__all__ = ["NODAL_MASSES", "LumpedNodalMass"]


class LumpedNodalMass(NodalMass):
    r"""The lumped grid mass of a :class:`PointGrid`: :math:`v = (mv)/m`,
    :math:`v^+ = v + \Delta t f/m` on the free components, fused into one pass where the
    conditions allow."""

    fusable = True

    def stable_factor(self, nodal, need: bool, top: float) -> float:
        """Called after P2G (``nodal`` its array, ``top`` the largest nodal mass, ``need``: the
        step is the stable one): the factor on the stable time of the state."""
        return 1.0

    def velocity(self, mass, mom, cv: int, active_min: float, guess=None, centroids=None,
                 forces: int | None = None, start: npt.NDArray | None = None) -> npt.NDArray:
        """Grid velocity from the nodal momenta ``mom[:, cv:cv+d]``, constrained (``forces``: the
        column of the step's forces where P2G mapped them into ``mom`` too, else None;
        ``start``: momenta added, the affine part of APIC/TPIC where P2G mapped it apart)."""
        g = self.layout
        v = np.empty((g.num_dofs, g.d))
        if start is not None:
            mom, cv = mom[:, cv:cv + g.d] + start, 0
        grid_velocity(mass, mom, cv, g.free, active_min, v)
        g.conditions.apply(v, centroids)
        return v

    def advance(self, mass, force, cf: int, active_min: float, weak_max: float, dt: float, v_old: npt.NDArray,
                centroids=None) -> npt.NDArray:
        r""":math:`v^+ = v + \Delta t\, a` from the nodal forces ``force[:, cf:cf+d]``, constrained."""
        g = self.layout
        v_new = np.empty((g.num_dofs, g.d))
        grid_advance(mass, force[:, cf:cf + g.d], g.free, active_min, weak_max, float(dt),
                        float(g.options.damping), v_old, v_new)
        g.conditions.apply(v_new, centroids, dt)
        return v_new


#: the compiled grid mass of each mass model
NODAL_MASSES = {Lumped: LumpedNodalMass, Consistent: ConsistentNodalMass, FMPM: FMPMNodalMass}
