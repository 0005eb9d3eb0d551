"""Rigid colliders given as shapes: a signed distance (:func:`plane`, :func:`disk`, :func:`box`,
:func:`polygon`, or any :class:`Shape`) in prescribed translation (:class:`Collider`), with non-penetration and Coulomb
friction at the grid nodes it touches and its reaction recorded each step
(:class:`~fempm.colliders.grid.ColliderContact`; ``ExplicitSolver(colliders=[...])``,
``Scene(colliders=[...])``)."""

from fempm.colliders.collider import Collider
from fempm.colliders.grid import ColliderContact
from fempm.colliders.shapes import Box, Disk, Plane, Polygon, Shape, box, disk, plane, polygon

__all__ = ["Box", "Collider", "ColliderContact", "Disk", "Plane", "Polygon", "Shape", "box", "disk", "plane", "polygon"]
