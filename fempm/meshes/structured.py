"""DOLFINx's structured meshes as the scenes make them: the same functions, each call counted
to the set-up's ``mesh_s`` (:mod:`fempm.timings`)."""

from __future__ import annotations

import dolfinx.mesh
from dolfinx.mesh import CellType, Mesh

from fempm.timings import timed

__all__ = ["CellType", "Mesh", "create_box", "create_interval", "create_rectangle", "create_unit_cube",
           "create_unit_square"]

create_interval = timed("mesh_s")(dolfinx.mesh.create_interval)
create_rectangle = timed("mesh_s")(dolfinx.mesh.create_rectangle)
create_box = timed("mesh_s")(dolfinx.mesh.create_box)
create_unit_square = timed("mesh_s")(dolfinx.mesh.create_unit_square)
create_unit_cube = timed("mesh_s")(dolfinx.mesh.create_unit_cube)
