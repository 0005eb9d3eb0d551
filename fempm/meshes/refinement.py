"""Uniform refinement of a distributed mesh on every rank: a large unstructured mesh made from
a coarse one that gmsh meshes quickly on rank 0 (each refinement splits every triangle into 4,
every tetrahedron into 8, halving the edges)."""

from __future__ import annotations

import dolfinx.io.gmsh
import dolfinx.mesh
import numpy as np

__all__ = ["MAX_REFINE", "check_refine", "refined"]

#: more uniform refinements than this is an error (8^8 = 1.7e7 tetrahedra per coarse one)
MAX_REFINE = 8


def check_refine(refine: int) -> int:
    """``refine`` as a number of refinements: an integer in [0, :data:`MAX_REFINE`], else a
    ValueError naming it."""
    if isinstance(refine, bool) or not isinstance(refine, (int, np.integer)) or not 0 <= refine <= MAX_REFINE:
        raise ValueError(f"refine={refine!r} must be a whole number of uniform refinements in [0, {MAX_REFINE}]")
    return int(refine)


def refined(data: dolfinx.io.gmsh.MeshData, times: int) -> dolfinx.io.gmsh.MeshData:
    """``data``'s mesh split uniformly ``times`` times, its cell and facet tags passed to the
    children (``dolfinx.mesh.refine``, Plaza's algorithm; the children of a cell stay on its
    rank, without ghost cells, as the meshes gmsh's reader makes).

    Args:
        data: A mesh of triangles or tetrahedra with its tags (DOLFINx ``MeshData``).
        times: The number of refinements (0: ``data`` itself).

    Returns:
        The refined ``MeshData`` (the physical groups kept; ridge and peak tags dropped).

    Raises:
        ValueError: A mesh of quadrilaterals or hexahedra (DOLFINx refines simplices only).

    Note:
        Collective.
    """
    times = check_refine(times)
    mesh, cell_tags, facet_tags = data.mesh, data.cell_tags, data.facet_tags
    if times and mesh.topology.cell_type not in (dolfinx.mesh.CellType.triangle, dolfinx.mesh.CellType.tetrahedron,
                                                 dolfinx.mesh.CellType.interval):
        raise ValueError(f"refine={times}: uniform refinement splits intervals, triangles and tetrahedra only, not "
                         f"{mesh.topology.cell_type.name} cells; mesh them at the cell size wanted")
    tdim = mesh.topology.dim
    for _ in range(times):
        mesh.topology.create_entities(1)
        mesh.topology.create_connectivity(tdim - 1, tdim)
        option = dolfinx.mesh.RefinementOption.parent_cell_and_facet
        fine, parent_cell, parent_facet = dolfinx.mesh.refine(mesh, partitioner=None, option=option)
        fine.topology.create_connectivity(tdim - 1, tdim)
        if cell_tags is not None:
            cell_tags = dolfinx.mesh.transfer_meshtag(cell_tags, fine, parent_cell)
        if facet_tags is not None:
            facet_tags = dolfinx.mesh.transfer_meshtag(facet_tags, fine, parent_cell, parent_facet)
        mesh = fine
    if times:
        mesh.name = data.mesh.name
        for tags, name in ((cell_tags, "cell_tags"), (facet_tags, "facet_tags")):
            if tags is not None:
                tags.name = name
    return dolfinx.io.gmsh.MeshData(mesh, cell_tags, facet_tags, None, None, data.physical_groups)
