"""Grid conditions: fixed, slip, prescribed and frictional walls (chosen by position, or on
tagged facets with their normals: :func:`tagged`), the contact patches of a wall that shares
its normal impulse by depth, absorbing dashpots (:func:`absorbing`); pressures and tractions
on tagged parts of the body's surface (:func:`surface_load`), and a traction on the mesh's own
boundary as the finite element's consistent nodal load (:func:`consistent_weights`)."""

from fempm.boundary.absorbing import Dashpot, absorbing
from fempm.boundary.conditions import GridConditions
from fempm.boundary.consistent_load import consistent_weights
from fempm.boundary.surface import SurfaceLoad, surface_load
from fempm.boundary.tagged import tagged
from fempm.boundary.walls import (
    Fixed,
    Friction,
    Prescribed,
    Slip,
    fixed,
    fixed_on_facets,
    friction,
    locate_dofs,
    prescribed,
    slip,
)

__all__ = [
    "Dashpot",
    "GridConditions",
    "Fixed",
    "Friction",
    "Prescribed",
    "Slip",
    "SurfaceLoad",
    "absorbing",
    "consistent_weights",
    "fixed",
    "fixed_on_facets",
    "friction",
    "locate_dofs",
    "prescribed",
    "slip",
    "surface_load",
    "tagged",
]
