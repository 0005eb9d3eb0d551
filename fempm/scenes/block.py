"""Hanging block under extreme self-weight (docs/verification.md) and its continuity measure."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fempm.boundary.walls import fixed
from fempm.materials.neo_hookean import NeoHookean
from fempm.meshes import structured as dm
from fempm.meshes.generators import unstructured_rectangle
from fempm.particles.corners import box_corners
from fempm.particles.particle_set import Particles
from fempm.particles.seeding import per_direction
from fempm.scene.definition import Scene, check_counts, checked
from fempm.stepping.loads import Loads
from fempm.stepping.options import StepOptions
from fempm.transfer.domains import step_domain

__all__ = ["hanging_block", "largest_neighbour_gap"]


@checked(positive=("E", "rho"), non_negative=("g",))
def hanging_block(
    *, cells: int = 10, ppc: int = 9, domain: str = "point", mesh: str = "structured", scheme: str = "MUSL",
    flip: float = 0.99, mass: str = "lumped", cfl: float = 0.4, t_end: float = 0.5, g: float = 1000.0,
    E: float = 1e6, nu: float = 0.3, rho: float = 1050.0, frames: int = 10, refine: int = 0,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> Scene:
    r"""Unit block hanging from its top under extreme self-weight (docs/verification.md):
    neo-Hookean, :math:`\rho g L / E \approx 1`, so the block stretches to several times its
    length. The block is :math:`[0, 1] \times [-1, 0]`, the grid velocity is zero at y > -h/2
    (one clamped row of cells above the block), and the mesh reaches down to y = -4.

    ``mesh``: "structured" (``cells`` quadrilaterals per unit length) or "unstructured"
    (triangles of about that size, with a row of vertices on the block's top y = 0). Particles carry their lattice index
    ``fields["lattice"]`` (i, j) for the neighbour-gap measure; with ``domain="cpdi2"`` each particle is its lattice
    square, ``fields["corners"]``.

    Args:
        cells: Cells per unit length.
        ppc: Particles per cell, a lattice.
        mesh: "structured" (quadrilaterals) or "unstructured" (triangles).
        t_end: The end time in s.
        g: Gravity in m/s^2 (rho g L / E about 1 by default).
        E: Young's modulus in Pa.
        nu: Poisson's ratio.
        rho: The density in kg/m^3.
        refine: Uniform refinements of a coarser gmsh mesh: gmsh meshes at 2^refine times the cell size and every rank splits its triangles refine times (:mod:`fempm.meshes.refinement`; a large mesh made in parallel).
    """
    check_counts(cells=cells, ppc=ppc)
    h = 1.0 / cells
    box = [[-0.5, -4.0], [1.5, h]]
    if refine and mesh != "unstructured":
        raise ValueError(f"refine={refine} refines the gmsh mesh: it needs mesh='unstructured'")
    if mesh == "structured":
        m = dm.create_rectangle(comm, box, [int(round(2 / h)), int(round((4 + h) / h))], dm.CellType.quadrilateral)
    elif mesh == "unstructured":
        m = unstructured_rectangle(comm, h, size=(2.0, 4.0 + h), origin=(-0.5, -4.0), split_y=(0.0,), refine=refine)
    else:
        raise ValueError(f"unknown option mesh={mesh!r}; expected structured or unstructured")
    # particles on a regular lattice of spacing h / sqrt(ppc) (also on the triangle mesh)
    n = cells * per_direction(ppc, 2)
    s = (np.arange(n) + 0.5) / n
    X, Y = np.meshgrid(s, s - 1.0, indexing="ij")
    x = np.column_stack([X.ravel(), Y.ravel()]) if comm.rank == 0 else np.zeros((0, 2))
    lattice = np.column_stack(np.unravel_index(np.arange(n * n), (n, n))) if comm.rank == 0 else np.zeros((0, 2))
    vol = (1.0 / n) ** 2
    fields = {"lattice": lattice.astype(float), "lp": np.full((len(x), 2), 0.5 / n)}
    if step_domain(domain).tracks_corners:  # each particle is its lattice square, tracked by its four corners
        fields["corners"] = box_corners(x, fields["lp"])
    p = Particles(m, x, rho * vol, vol, fields=fields)
    params = dict(cells=cells, ppc=ppc, domain=domain, mesh=mesh, scheme=scheme, flip=flip, mass=mass, cfl=cfl, g=g, E=E,
                  nu=nu, rho=rho, spacing=1.0 / n, h=h, **({"refine": refine} if refine else {}))
    return Scene(
        name="hanging_block", mesh=m, particles=p, materials=[NeoHookean(E, nu)], t_end=t_end, frames=frames,
        bcs=lambda V: [fixed(V, lambda x: x[1] > -0.5 * h)], loads=Loads(body_force=(0.0, -g)),
        options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl, domain=domain), params=params,
    )


def largest_neighbour_gap(particles) -> float:
    """Largest distance between lattice neighbours (right and lower) over all ranks, gathered
    on every rank (the hanging block's continuity measure)."""
    comm = particles.comm
    lat = np.concatenate(comm.allgather(particles.fields["lattice"].astype(np.int64)))
    x = np.concatenate(comm.allgather(particles.x))
    n = int(lat.max(initial=0)) + 1
    grid = np.full((n, n, 2), np.nan)
    grid[lat[:, 0], lat[:, 1]] = x
    gaps = [np.linalg.norm(np.diff(grid, axis=a), axis=-1) for a in (0, 1)]
    return float(max(np.nanmax(g_) for g_ in gaps))
