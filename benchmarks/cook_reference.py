"""Cook's membrane's finite element reference, refined in h and in degree.

    python benchmarks/cook_reference.py [--h 2 1 0.5] [--degrees 2 3 4]
    python benchmarks/cook_reference.py --seeding --h 4 2 1 0.5

prints, for nu = 1/3 and 0.4999, the vertical displacement of C per unit load of the Taylor-Hood
P_k/P_{k-1} solutions (:func:`fempm.scenes.cook.fe_reference`) on gmsh triangles of each size,
the order fitted to each degree's last three sizes and Richardson's value at it
(:func:`fempm.studies.scenes.fit`): the value :data:`fempm.studies.scenes.COOK_FE` records. The
clamped corners' singularities hold every degree to an order of about 1.

``--seeding``: at nu = 1/3, the quasi-static MPM answer (10 implicit steps, load 1e-4 so that
no particle crosses the panel's edge) with the scene's lattice at spacings h/2 (its default) and
h/4, and with particles seeded per triangle (``create_particles(mesh, ppc)``: each triangle's
particles hold exactly its area, so the P1 stiffness is integrated exactly) at 4 and 9 per
triangle, the traction on BC then a surface load on the tagged edge
(:func:`fempm.boundary.surface_load`), beside the displacement-based P1 finite element solution
on the same meshes: what point particles integrate, and the floor a P1 background has.
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
from fempm.scenes.cook import (CORNERS, EDGE, cook_membrane, corner_displacement, fe_reference, first_frequency,
                               value_at_corner)
from fempm.stepping import Loads, StepOptions
from fempm.studies.scenes import COOK_FE, fit

LOAD = 1e-4
QUASI_STATIC = {"integrator": "implicit", "dynamics": "quasi-static"}


def p1_fe(h: float, nu: float = 1 / 3) -> float:
    """u_y(C) per unit load of the displacement-based P1 solution on the scene's mesh of size h."""
    import dolfinx.fem
    import dolfinx.fem.petsc
    import ufl

    from fempm.materials.base import lame

    data = tagged_polygon(MPI.COMM_SELF, CORNERS, h, [0, 1, 0, 0])
    mesh = data.mesh
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    lam, mu = lame(1.0, nu)
    eps = lambda w: ufl.sym(ufl.grad(w))  # noqa: E731
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=data.facet_tags)
    a = (2 * mu * ufl.inner(eps(u), eps(v)) + lam * ufl.div(u) * ufl.div(v)) * ufl.dx
    L = ufl.inner(dolfinx.fem.Constant(mesh, np.array([0.0, 1.0 / EDGE])), v) * ds(1)
    bc = dolfinx.fem.dirichletbc(np.zeros(2), dolfinx.fem.locate_dofs_geometrical(V, lambda x: np.isclose(x[0], 0.0)), V)
    uh = dolfinx.fem.petsc.LinearProblem(a, L, bcs=[bc], petsc_options_prefix="cook_p1_", petsc_options={
        "ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}).solve()
    return float(value_at_corner(uh[0] if isinstance(uh, tuple) else uh)[1])


def lattice(h: float, factor: float) -> tuple[float, int]:
    """The scene's own particles at spacing h / factor: (u_y(C) per unit load, particles)."""
    scene = cook_membrane(h=h, spacing=h / factor, load=LOAD, frames=0)
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
    columns = [("lattice h/2 (default)", lambda h: lattice(h, 2)), ("lattice h/4", lambda h: lattice(h, 4)),
               ("4 per triangle", lambda h: per_cell(h, 4)), ("9 per triangle", lambda h: per_cell(h, 9)),
               ("P1 FE", lambda h: (p1_fe(h), 0))]
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
