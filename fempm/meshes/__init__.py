"""Background meshes: structured and gmsh meshes, their cells' geometry (coordinate map, affine
pull-back) and the CFL length of the cells."""

from fempm.meshes.generators import (
    MESHES,
    MeshFileError,
    read_msh,
    tagged_polygon,
    unstructured_box,
    unstructured_polygon,
    unstructured_rectangle,
)

__all__ = [
    "MESHES",
    "MeshFileError",
    "read_msh",
    "tagged_polygon",
    "unstructured_box",
    "unstructured_polygon",
    "unstructured_rectangle",
]
