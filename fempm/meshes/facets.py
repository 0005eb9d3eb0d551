r"""Facets of a mesh: their area vectors and what lies on either side of them.

A facet's area vector is its measure times its unit normal, :math:`\mathbf a_f = |f|\,\mathbf
n_f` (a point of measure 1 in 1D; a straight edge in 2D; a triangle, or a quadrilateral as half
the cross product of its diagonals, in 3D: exact for planar facets), pointing out of a chosen
cell beside it.
"""

from __future__ import annotations

import dolfinx.la
import dolfinx.mesh
import numpy as np
import numpy.typing as npt

__all__ = ["cells_beside", "facet_area_vectors", "facet_planes", "facet_sums", "nearest_row"]


def facet_area_vectors(mesh: dolfinx.mesh.Mesh, facets: npt.NDArray[np.int32],
                       cells: npt.NDArray[np.int32] | None = None) -> npt.NDArray:
    """The area vectors (len(facets), gdim) of local ``facets``, pointing out of ``cells`` (one
    local cell beside each facet; default the first cell of each facet's connectivity). Needs
    the facet-to-cell connectivity when ``cells`` is None."""
    tdim, gdim = mesh.topology.dim, mesh.geometry.dim
    fdim = tdim - 1
    facets = np.asarray(facets, dtype=np.int32)
    if not len(facets):
        return np.zeros((0, gdim))
    x = mesh.geometry.x[:, :gdim]
    nodes = dolfinx.mesh.entities_to_geometry(mesh, fdim, facets)
    p = x[nodes]  # (nf, nodes, gdim); the vertices first
    if gdim == 1:  # a point facet of an interval mesh: measure 1, the sign set below
        a = np.ones((len(facets), 1))
    elif gdim == 2:
        t = p[:, 1] - p[:, 0]
        a = np.stack([t[:, 1], -t[:, 0]], axis=1)
    elif nodes.shape[1] in (4, 9):  # a quadrilateral facet (vertices 0 1 3 2 round it)
        a = 0.5 * np.cross(p[:, 3] - p[:, 0], p[:, 2] - p[:, 1])
    else:
        a = 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    if cells is None:
        f2c = mesh.topology.connectivity(fdim, tdim)
        cells = np.array([f2c.links(f)[0] for f in facets], dtype=np.int32)
    centres = x[dolfinx.mesh.entities_to_geometry(mesh, tdim, np.asarray(cells, dtype=np.int32))].mean(axis=1)
    inward = np.einsum("fd,fd->f", p[:, 0] - centres, a) < 0  # a planar facet: any of its points
    a[inward] *= -1.0
    return a


def facet_planes(mesh: dolfinx.mesh.Mesh, facets: npt.NDArray[np.int32],
                 cells: npt.NDArray[np.int32] | None = None) -> tuple[npt.NDArray, npt.NDArray]:
    """(a point (the first vertex), the area vector) of each local facet, the area vectors as
    :func:`facet_area_vectors`."""
    nodes = dolfinx.mesh.entities_to_geometry(mesh, mesh.topology.dim - 1, np.asarray(facets, dtype=np.int32))
    return mesh.geometry.x[nodes[:, 0], : mesh.geometry.dim], facet_area_vectors(mesh, facets, cells)


def nearest_row(depth: npt.NDArray, slack: float) -> npt.NDArray[np.bool_]:
    """Which of some particles at distances ``depth`` from a facet's plane lie in the row
    nearest to it: within 1.5 times the smallest distance, plus ``slack`` (round-off)."""
    return depth <= 1.5 * depth.min() + slack


def facet_sums(mesh: dolfinx.mesh.Mesh, local: npt.NDArray) -> npt.NDArray:
    """Per local facet (owned and ghost), the sum over all ranks of each rank's ``local`` values
    of that facet. Collective."""
    sums = dolfinx.la.vector(mesh.topology.index_map(mesh.topology.dim - 1), 1, dtype=np.float64)
    sums.array[:] = local
    sums.scatter_reverse(dolfinx.la.InsertMode.add)
    sums.scatter_forward()
    return sums.array.copy()


def cells_beside(mesh: dolfinx.mesh.Mesh, flags: npt.NDArray[np.bool_]) -> npt.NDArray:
    """For each local facet (owned and ghost), the number of cells beside it, over all ranks,
    whose ``flags`` (one per owned cell) hold. Needs the cell-to-facet connectivity. Collective."""
    tdim = mesh.topology.dim
    fdim = tdim - 1
    cmap, fmap = mesh.topology.index_map(tdim), mesh.topology.index_map(fdim)
    links = np.asarray(mesh.topology.connectivity(tdim, fdim).array).reshape(cmap.size_local + cmap.num_ghosts, -1)
    counts = np.zeros(fmap.size_local + fmap.num_ghosts)
    np.add.at(counts, links[: len(flags)][flags].ravel(), 1.0)
    return facet_sums(mesh, counts)
