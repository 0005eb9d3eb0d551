"""What the scenes that run in 2D (plane strain) and 3D share: the ``dim`` option, the default
lattice of particles per cell, the structured mesh of a box, and vectors along the axes."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fempm.meshes import structured as dm

__all__ = ["DIMS", "axis", "block_mesh", "check_dim", "lattice_ppc"]

#: the dimensions a scene with a ``dim`` option runs in
DIMS = (2, 3)


def check_dim(dim: int) -> int:
    """``dim`` as 2 or 3, else a ValueError naming it."""
    if isinstance(dim, bool) or dim not in DIMS:
        raise ValueError(f"dim={dim!r} must be 2 (plane strain) or 3")
    return int(dim)


def lattice_ppc(ppc: int | None, dim: int) -> int:
    """Particles per cell: ``ppc``, or by default a lattice of 2 per direction (4 in 2D, 8 in 3D)."""
    return 2**dim if ppc is None else ppc


def block_mesh(comm: MPI.Comm, lo, hi, n) -> dm.Mesh:
    """Quadrilaterals (2D) or hexahedra (3D) on the box ``[lo, hi]``, ``n`` cells per direction
    (the dimension that of ``lo``)."""
    if len(lo) == 2:
        return dm.create_rectangle(comm, [list(lo), list(hi)], list(n), dm.CellType.quadrilateral)
    return dm.create_box(comm, [list(lo), list(hi)], list(n), dm.CellType.hexahedron)


def axis(k: int, dim: int, length: float = 1.0) -> tuple[float, ...]:
    """``length`` times the unit vector along axis ``k`` in ``dim`` dimensions."""
    e = np.zeros(dim)
    e[k] = length
    return tuple(float(v) for v in e)
