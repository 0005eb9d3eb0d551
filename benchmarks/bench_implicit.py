"""The implicit step against a plain DOLFINx finite element solve of the same problem, in one run.

    python benchmarks/bench_implicit.py [--h 1] [--steps 10] [--repeats 3] [--profile] [--json FILE]

Cook's membrane (nu = 1/3, E = 1, load 1e-3, :func:`fempm.scenes.cook.cook_membrane`) on gmsh
triangles of size ``--h``, quasi-static implicit MPM in ``--steps`` load steps
(``StepOptions(integrator="implicit", dynamics="quasi-static")``, ``fempm.scene.run`` without
output; timed from the built scene, its mesh and particles, as DOLFINx's solve is from its
built problem: ``run`` locates the particles, tabulates the basis, builds the tangent's pattern
and takes the steps with their diagnostics; building the scene is reported besides, with the
ratio it would give), against DOLFINx on the same mesh: P1 displacements, a compressible
neo-Hookean solid of the same E and nu, the traction ramped in the same load steps, each solved
by PETSc SNES (Newton, line search ``basic``, MUMPS LU; ``dolfinx.fem.petsc.NonlinearProblem``). Both are
warmed up once (numba's kernels and the forms compiled), then timed ``--repeats`` times
alternately; the medians and their ratio (fempm over DOLFINx) are printed. ``--profile``: the
fempm run's 25 largest functions by their own time (``cProfile``).
"""

from __future__ import annotations

import argparse
import cProfile
import json
import pstats
import statistics
import time

import fempm  # noqa: F401  (dolfinx_solver before dolfinx)
import numpy as np
from mpi4py import MPI

from fempm.scenes.cook import CORNERS, EDGE, cook_membrane, value_at_corner
from fempm.stepping import StepOptions

LOAD, NU, E = 1e-3, 1.0 / 3.0, 1.0


def mpm(h: float, steps: int) -> tuple[float, float, float]:
    """(seconds of the run, u_y(C) / load, seconds of building the scene) of the implicit MPM run."""
    t0 = time.perf_counter()
    scene = cook_membrane(h=h, nu=NU, E=E, load=LOAD, frames=0)
    scene.options = StepOptions(integrator="implicit", dynamics="quasi-static", load_ramp=scene.t_end)
    scene.dt = scene.t_end / steps
    t1 = time.perf_counter()
    out = fempm.scene.run(scene, None, progress=False)
    return time.perf_counter() - t1, float(out["corner_displacement"][1]) / LOAD, t1 - t0


class FESolve:
    """The neo-Hookean panel in DOLFINx, its forms compiled once."""

    def __init__(self, h: float, steps: int):
        import dolfinx.fem
        import dolfinx.fem.petsc
        import ufl

        from fempm.meshes import unstructured_polygon

        self.steps = steps
        mesh = unstructured_polygon(MPI.COMM_WORLD, CORNERS, h)
        V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
        self.u = u = dolfinx.fem.Function(V)
        v = ufl.TestFunction(V)
        mu, lam = E / (2 * (1 + NU)), E * NU / ((1 + NU) * (1 - 2 * NU))
        F = ufl.variable(ufl.Identity(2) + ufl.grad(u))
        J = ufl.det(F)
        C = F.T * F
        psi = mu / 2 * (ufl.tr(C) - 2) - mu * ufl.ln(J) + lam / 2 * ufl.ln(J) ** 2
        P = ufl.diff(psi, F)
        facets = dolfinx.mesh.locate_entities_boundary(mesh, 1, lambda x: np.isclose(x[0], CORNERS[1, 0]))
        tags = dolfinx.mesh.meshtags(mesh, 1, facets, np.full(len(facets), 1, dtype=np.int32))
        ds = ufl.Measure("ds", domain=mesh, subdomain_data=tags)
        self.t = dolfinx.fem.Constant(mesh, np.zeros(2))
        residual = ufl.inner(P, ufl.grad(v)) * ufl.dx - ufl.inner(self.t, v) * ds(1)
        clamp = dolfinx.fem.locate_dofs_geometrical(V, lambda x: np.isclose(x[0], 0.0))
        bc = dolfinx.fem.dirichletbc(np.zeros(2), clamp, V)
        self.problem = dolfinx.fem.petsc.NonlinearProblem(
            residual, u, bcs=[bc], petsc_options_prefix="bench_implicit_fe_",
            petsc_options={"snes_type": "newtonls", "snes_linesearch_type": "basic", "snes_rtol": 1e-10,
                           "snes_atol": 1e-12, "ksp_type": "preonly", "pc_type": "lu",
                           "pc_factor_mat_solver_type": "mumps", "snes_error_if_not_converged": True})

    def __call__(self) -> tuple[float, float]:
        """(seconds, u_y(C) / load) of the load steps from rest."""
        self.u.x.array[:] = 0.0
        t0 = time.perf_counter()
        for k in range(1, self.steps + 1):
            self.t.value[:] = (0.0, LOAD / EDGE * k / self.steps)
            self.problem.solve()
        wall = time.perf_counter() - t0
        return wall, float(value_at_corner(self.u)[1]) / LOAD


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--h", type=float, default=1.0)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--json", help="write the result to this file")
    a = ap.parse_args(argv)
    fe = FESolve(a.h, a.steps)
    fe(), mpm(a.h, a.steps)  # warm-up: forms and kernels compiled
    t_fe, t_mpm, t_build = [], [], []
    for _ in range(a.repeats):
        wall, u_fe = fe()
        t_fe.append(wall)
        wall, u_mpm, build = mpm(a.h, a.steps)
        t_mpm.append(wall)
        t_build.append(build)
    fe_s, mpm_s, build_s = (statistics.median(t) for t in (t_fe, t_mpm, t_build))
    ratio = mpm_s / fe_s
    result = {"h": a.h, "steps": a.steps, "mpm_s": mpm_s, "fe_s": fe_s, "ratio": ratio, "scene_build_s": build_s,
              "ratio_with_build": (mpm_s + build_s) / fe_s, "u_mpm": u_mpm, "u_fe": u_fe, "ranks": MPI.COMM_WORLD.size}
    if MPI.COMM_WORLD.rank == 0:
        print(f"Cook, h = {a.h:g}, {a.steps} quasi-static steps: fempm {mpm_s:.3f} s, DOLFINx neo-Hookean "
              f"{fe_s:.3f} s: {ratio:.2f}x (u_y(C)/load {u_mpm:.3f} and {u_fe:.3f}; medians of {a.repeats}); "
              f"building the scene {build_s:.3f} s more ({result['ratio_with_build']:.2f}x with it)")
        if a.json:
            with open(a.json, "w") as f:
                json.dump(result, f, indent=1)
    if a.profile:
        prof = cProfile.Profile()
        prof.enable()
        mpm(a.h, a.steps)
        prof.disable()
        if MPI.COMM_WORLD.rank == 0:
            pstats.Stats(prof).sort_stats("tottime").print_stats(25)


if __name__ == "__main__":
    main()
