"""The CFL length of the cells."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from fempm.meshes.geometry import CHUNK, coordinate_map

__all__ = ["cell_sizes"]


def cell_sizes(mesh) -> npt.NDArray:
    """Smallest vertex-to-vertex distance of each local cell (the CFL length)."""

    _, dofmap = coordinate_map(mesh)
    nv = {"interval": 2, "triangle": 3, "quadrilateral": 4, "tetrahedron": 4, "hexahedron": 8}[
        mesh.topology.cell_type.name
    ]
    dofmap = np.asarray(dofmap)
    i, j = np.triu_indices(nv, 1)
    out = np.empty(len(dofmap))
    for start in range(0, len(dofmap), CHUNK):  # chunks of cells bound the temporaries
        xc = mesh.geometry.x[dofmap[start : start + CHUNK, :nv]]
        out[start : start + CHUNK] = np.linalg.norm(xc[:, i] - xc[:, j], axis=2).min(axis=1)
    return out
