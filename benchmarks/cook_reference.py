"""Cook's membrane's finite element reference, refined in h and in degree.

    python benchmarks/cook_reference.py [--h 2 1 0.5] [--degrees 2 3 4]
    python benchmarks/cook_reference.py --seeding --h 4 2 1 0.5

prints, for nu = 1/3 and 0.4999, the vertical displacement of C per unit load of the Taylor-Hood
P_k/P_{k-1} solutions (:func:`fempm.scenes.cook.fe_reference`) on gmsh triangles of each size,
the order fitted to each degree's last three sizes and Richardson's value at it
(:func:`fempm.studies.scenes.fit`): the value :data:`fempm.studies.scenes.COOK_FE` records. The
clamped corners' singularities hold every degree to an order of about 1.

``--seeding``: at nu = 1/3, the quasi-static MPM answer (10 implicit steps, load 1e-4 so that
no particle crosses the panel's edge) with the scene's default seeding (4 particles per
triangle, each triangle's particles holding exactly its area so that the P1 stiffness is
integrated exactly, the traction the consistent nodal load), 9 per triangle, the scene's
lattice at spacings h/2 (its default before 2026-12) and h/4, and 9 per triangle with the
traction a surface load on the tagged edge (:func:`fempm.boundary.surface_load`: the right
total force on the particles nearest the edge), beside the displacement-based P1 finite element
solution on the same meshes (:func:`fempm.scenes.cook.displacement_reference`).
"""

import argparse
import dataclasses

import fempm  # noqa: F401  (before dolfinx)
import numpy as np
from mpi4py import MPI

from fempm.boundary import fixed, surface_load
from fempm.materials import LinearElastic
from fempm.meshes import tagged_polygon
from fempm.scene import Scene, run
from fempm.scenes.cook import (CORNERS, EDGE, cook_membrane, corner_displacement, displacement_reference, fe_reference,
                               first_frequency)
from fempm.stepping import Loads, StepOptions
from fempm.studies.scenes import COOK_FE, fit

LOAD = 1e-4
QUASI_STATIC = {"integrator": "implicit", "dynamics": "quasi-static"}


def scene_answer(h: float, **seeding) -> tuple[float, int]:
    """The scene's quasi-static answer with its ``seeding`` (``spacing`` or ``ppc``; none: its
    default): (u_y(C) per unit load, particles)."""
    scene = cook_membrane(h=h, load=LOAD, frames=0, **seeding)
    scene.options = dataclasses.replace(scene.options, **QUASI_STATIC)
    scene.dt = scene.t_end / 10
    s = run(scene, None, progress=False)
    return s["corner_displacement"][1] / LOAD, s["particles"]


def per_cell(h: float, ppc: int) -> tuple[float, int]:
    """``ppc`` particles seeded in each triangle, the traction a surface load on BC."""
    data = tagged_polygon(MPI.COMM_WORLD, CORNERS, h, [0, 1, 0, 0])
    p = fempm.create_particles(data.mesh, ppc, density=1.0)
    load = surface_load(p, data.facet_tags, 1, traction=(0.0, LOAD / EDGE))
    t_end = 12.0 / first_frequency(1.0, 1 / 3, 1.0)
    scene = Scene(name="cook", mesh=data.mesh, particles=p, materials=[LinearElastic(1.0, 1 / 3)], t_end=t_end,
                  frames=0, bcs=lambda V: [fixed(V, lambda x: x[0] < 1e-9)], loads=Loads(surface=[load]),
                  options=StepOptions(**QUASI_STATIC), dt=t_end / 10,
                  results=lambda scene, solver: {"c": corner_displacement(solver.particles).tolist()})
    s = run(scene, None, progress=False)
    return s["c"][1] / LOAD, s["particles"]


def seeding(hs: list[float]) -> None:
    ref = COOK_FE[1 / 3]
    columns = [("4 per triangle, consistent load (default)", lambda h: scene_answer(h)),
               ("9 per triangle, consistent load", lambda h: scene_answer(h, ppc=9)),
               ("lattice h/2", lambda h: scene_answer(h, spacing=h / 2)),
               ("lattice h/4", lambda h: scene_answer(h, spacing=h / 4)),
               ("9 per triangle, surface_load", lambda h: per_cell(h, 9)),
               ("P1 FE", lambda h: (displacement_reference(1 / 3, h)[1], 0))]
    print(f"u_y(C) per unit load at nu = 1/3 against {ref} (error %, particles)")
    print("| h | " + " | ".join(c for c, _ in columns) + " |")
    print("|---|" + "---|" * len(columns))
    for h in hs:
        cells = []
        for _, f in columns:
            u, n = f(h)
            cells.append(f"{u:.4f} ({100 * (u / ref - 1):+.2f} %{f', {n}' if n else ''})")
        print(f"| {h:g} | " + " | ".join(cells) + " |", flush=True)


def main() -> None:
    a = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    a.add_argument("--h", type=float, nargs="+", default=[2.0, 1.0, 0.5])
    a.add_argument("--degrees", type=int, nargs="+", default=[2, 3, 4])
    a.add_argument("--seeding", action="store_true", help="the MPM answers of the seedings beside P1 FE")
    args = a.parse_args()
    if args.seeding:
        seeding(args.h)
        return
    print("| nu | element | " + " | ".join(f"h = {h:g}" for h in args.h) + " | order | Richardson |")
    print("|---|---|" + "---|" * len(args.h) + "---|---|")
    for nu in (1 / 3, 0.4999):
        for k in args.degrees:
            u = np.array([fe_reference(nu, h, degree=k)[1] for h in args.h])
            order, extrapolated = fit(np.array(args.h), u, np.nan)  # the last three sizes' order
            print(f"| {nu:.4g} | P{k}/P{k - 1} | " + " | ".join(f"{x:.4f}" for x in u)
                  + f" | {order:.2f} | {extrapolated:.4f} |")


if __name__ == "__main__":
    main()
