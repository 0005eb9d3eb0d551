"""Two colliding elastic disks (docs/verification.md), or spheres (``dim=3``)."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fempm.materials.linear_elastic import LinearElastic
from fempm.meshes import structured as dm
from fempm.meshes.generators import MESHES, read_msh, unstructured_box
from fempm.particles.seeding import create_particles
from fempm.scene.definition import Scene, check_counts, checked
from fempm.scenes.dims import check_dim, lattice_ppc
from fempm.stepping.contact import Contact
from fempm.stepping.options import StepOptions

__all__ = ["two_disks"]


@checked(positive=("E", "rho", "radius"), non_negative=("speed", "friction"))
def two_disks(
    *, mesh: str | dm.Mesh = "structured", cells: int = 20, ppc: int | None = None, scheme: str = "MUSL", flip: float = 1.0,
    mass: str = "lumped", cfl: float = 0.4, t_end: float = 3.0, E: float = 1000.0, nu: float = 0.3,
    rho: float = 1000.0, speed: float = 0.1, radius: float = 0.2, frames: int = 30, contact: bool = False,
    friction: float = 0.0, dim: int = 2, comm: MPI.Comm = MPI.COMM_WORLD,
) -> Scene:
    """Two elastic disks (Sulsky, Chen and Schreyer 1994) on the unit square, plane strain.

    Disks of radius 0.2 at (0.2, 0.2) and (0.8, 0.8) moving at +-(0.1, 0.1); contact through
    the single-valued grid velocity, or with ``contact`` one velocity field per disk
    (``fields["disk"]``, :class:`fempm.stepping.contact.Contact` with Coulomb ``friction``); no boundary
    conditions (the disks never reach the walls).
    ``mesh``: "structured" (quadrilaterals, ``cells`` per side), "unstructured"
    (triangles from ``meshes/unit_square_tri.msh``) or a mesh of the unit square (e.g. of a
    benchmark's size; ``cells`` unused). With ``dim=3``: two spheres in the unit cube, at
    (0.2, 0.2, 0.2) and (0.8, 0.8, 0.8) moving at +-(0.1, 0.1, 0.1), on hexahedra
    ("structured") or gmsh tetrahedra of size ``1 / cells`` ("unstructured").

    Args:
        mesh: "structured" (quadrilaterals, ``cells`` per side), "unstructured" (the triangles of
            meshes/unit_square_tri.msh) or a DOLFINx mesh of the unit square.
        cells: Cells along each side of the unit square.
        ppc: Particles per cell, a lattice (None: 4 in 2D, 8 in 3D).
        t_end: The end time in s.
        E: Young's modulus in Pa.
        nu: Poisson's ratio.
        rho: The density in kg/m^3.
        speed: Each disk's speed along each axis in m/s.
        radius: The disks' radius in m.
        contact: One velocity field per disk with Coulomb contact (else one field).
        friction: The contact's Coulomb coefficient.
        dim: 2 (disks, plane strain) or 3 (spheres).
    """
    dim = check_dim(dim if not isinstance(mesh, dm.Mesh) else mesh.geometry.dim)
    ppc = lattice_ppc(ppc, dim)
    check_counts(cells=cells, ppc=ppc)
    if friction and not contact:
        raise ValueError(f"friction={friction} needs contact=True: without contact the disks share one grid velocity "
                         "and no friction acts between them")
    if not 0.0 < radius <= 0.2:
        raise ValueError(f"radius={radius} must lie in (0, 0.2]: the disks, centred at (0.2, 0.2) and (0.8, 0.8), "
                         "must lie in the unit square and apart")
    if isinstance(mesh, dm.Mesh):
        m = mesh
    elif mesh == "structured" and dim == 3:
        m = dm.create_unit_cube(comm, cells, cells, cells, dm.CellType.hexahedron)
    elif mesh == "structured":
        m = dm.create_unit_square(comm, cells, cells, dm.CellType.quadrilateral)
    elif mesh == "unstructured" and dim == 3:
        m = unstructured_box(comm, 1.0 / cells)
    elif mesh == "unstructured":
        m = read_msh(MESHES / "unit_square_tri.msh", comm, gdim=2).mesh
    else:
        raise ValueError(f"unknown option mesh={mesh!r}; expected structured or unstructured")
    centres = np.array([[0.2] * dim, [0.8] * dim])

    def in_disks(x):
        return ((np.linalg.norm(x[:dim].T - centres[0], axis=1) < radius)
                | (np.linalg.norm(x[:dim].T - centres[1], axis=1) < radius))

    p = create_particles(m, ppc, density=rho, where=in_disks)
    lower = np.linalg.norm(p.x - centres[0], axis=1) < radius
    p.fields["v"] = np.where(lower[:, None], speed, -speed) * np.ones((len(p), dim))
    p.fields["disk"] = (~lower).astype(np.int32)
    params = dict(mesh=mesh if isinstance(mesh, str) else "given", cells=cells, ppc=ppc, scheme=scheme, flip=flip,
                  mass=mass, cfl=cfl, E=E, nu=nu, rho=rho,
                  contact=contact, friction=friction, **({"dim": dim} if dim == 3 else {}))
    return Scene(
        name="two_disks", mesh=m, particles=p, materials=[LinearElastic(E, nu)], t_end=t_end, frames=frames,
        options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl), params=params,
        contact=Contact(friction=friction, field="disk") if contact else None,
    )
