r"""# Particle-to-grid projection on an unstructured gmsh mesh

A plate with a hole (`meshes/plate_with_hole.msh`, triangles) carries particles seeded 4 per
cell with a random jitter. Each particle holds the value of a smooth field

$$ f(x, y) = \sin(2\pi x)\cos(2\pi y) + x^2 $$

which we map to the grid by the mass-weighted least-squares (Galerkin) projection
$\sum_j m_{ij} F_j = \sum_p M_p f_p N_i(x_p)$:

* **consistent** mass $m_{ij} = \sum_p M_p N_i(x_p) N_j(x_p)$ (PETSc matrix, CG + Jacobi),
* **lumped** mass $m_i = \sum_p M_p N_i(x_p)$ (a division per dof).

We compare their $L^2$ errors for P1 and P2 (P2 only consistent: its Lagrange vertex basis
functions integrate to zero, so lumped vertex masses are not positive), check that mass and
momentum are carried to the grid exactly, and write the fields for ParaView (VTX) and a PNG.

Run: `.venv/bin/python demos/projection_unstructured.py [--ppc 4] [--out output/projection]`
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import fempm  # imports dolfinx_solver first when installed
import dolfinx
import dolfinx.fem
import dolfinx.io
import numpy as np
import ufl
from mpi4py import MPI

from fempm.verification.errors import l2_error
from fempm.meshes import read_msh

HERE = Path(__file__).resolve().parent
DEFAULT_MESH = HERE.parent / "meshes" / "plate_with_hole.msh"


def field(x):
    """The particle field, with x of shape (3, n) (DOLFINx convention)."""
    return np.sin(2 * np.pi * x[0]) * np.cos(2 * np.pi * x[1]) + x[0] ** 2


def field_ufl(mesh):
    x = ufl.SpatialCoordinate(mesh)
    return ufl.sin(2 * ufl.pi * x[0]) * ufl.cos(2 * ufl.pi * x[1]) + x[0] ** 2


#: the small run its page in the docs shows, executed when the site is built (docs/demo_runs.py)
DOCS_RUN = ["--ppc", "4"]


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", type=Path, default=DEFAULT_MESH)
    parser.add_argument("--ppc", type=int, default=4)
    parser.add_argument("--jitter", type=float, default=0.5)
    parser.add_argument("--out", type=Path, default=Path("output/projection"))
    parser.add_argument("--no-plot", action="store_true", help="skip the PNG")
    args = parser.parse_args(argv)
    comm = MPI.COMM_WORLD

    # ## The mesh and the particles
    mesh = read_msh(args.mesh, comm, gdim=2).mesh
    particles = fempm.create_particles(mesh, args.ppc, density=1.0, jitter=args.jitter, seed=7)
    n = particles.num_global
    area = comm.allreduce(particles.volume.sum())

    # ## Projections
    # The particle values are the field at the particle positions; the same callable form as
    # `Function.interpolate` is accepted.
    results = {"particles": n, "area": area, "cases": []}
    out_fields = []
    for degree, mass in [(1, "lumped"), (1, "consistent"), (2, "consistent")]:
        V = dolfinx.fem.functionspace(mesh, ("Lagrange", degree))
        t0 = time.perf_counter()
        projector = fempm.Projector(V, particles, mass=mass)
        F = projector.project(field)
        wall = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
        F.name = f"f_P{degree}_{mass}"
        err = l2_error(F, field_ufl(mesh))
        # Conservation: the grid holds the particles' total mass and "momentum" sum_p M_p f_p.
        one = dolfinx.fem.Function(V)
        one.x.array[:] = 1.0
        m_grid, p_grid = projector.grid_total(one)[0], projector.grid_total(F)[0]
        fp = field(np.vstack([particles.x.T, np.zeros((1, len(particles)))]))
        m_part = comm.allreduce(particles.mass.sum())
        p_part = comm.allreduce((particles.mass * fp).sum())
        case = {
            "space": f"P{degree}",
            "mass": mass,
            "L2 error": err,
            "time [s]": wall,
            "mass defect": abs(m_grid - m_part) / m_part,
            "momentum defect": abs(p_grid - p_part) / abs(p_part),
            "KSP iterations": projector.iterations,
        }
        results["cases"].append(case)
        out_fields.append(F)
        if comm.rank == 0:
            print(
                f"P{degree} {mass:10s}  L2 error {err:.3e}  time {wall:.3f} s  "
                f"mass defect {case['mass defect']:.1e}  momentum defect {case['momentum defect']:.1e}"
            )

    # ## Output for ParaView: one VTX file per space (ADIOS2)
    args.out.mkdir(parents=True, exist_ok=True)
    for F in out_fields:
        with dolfinx.io.VTXWriter(comm, args.out / f"{F.name}.bp", [F], engine="BP4") as vtx:
            vtx.write(0.0)
    if comm.rank == 0:
        (args.out / "summary.json").write_text(json.dumps(results, indent=2))

    # ## A picture: particles coloured by their value, and the consistent P1 field
    if not args.no_plot:
        from fempm.io.plot import plot_projection

        plot_projection(out_fields[1], particles, fp, args.out / "projection.png")
    return results


if __name__ == "__main__":
    main()
