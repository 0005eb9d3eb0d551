"""Grid conditions: fixed, slip, prescribed and frictional walls (chosen by position, or on
tagged facets with their normals: :func:`tagged`), and the contact patches of a wall that
shares its normal impulse by depth."""

from fempm.boundary.conditions import GridConditions
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
    "GridConditions",
    "Fixed",
    "Friction",
    "Prescribed",
    "Slip",
    "fixed",
    "fixed_on_facets",
    "friction",
    "locate_dofs",
    "prescribed",
    "slip",
    "tagged",
]
