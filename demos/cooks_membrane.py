r"""# Cook's membrane: MPM on an unstructured mesh against a DOLFINx finite element reference

The tapered panel $A(0,0)$, $B(48,44)$, $C(48,60)$, $D(0,44)$ is clamped on its left edge and
loaded on its right edge by a uniform vertical shear traction of total force $F$. The material
is linear elastic (small strain, $E = 1$, plane strain) with $\nu = 1/3$ and the nearly
incompressible $\nu = 0.4999$, where low-order displacement elements lock. The quantity of
interest is the vertical displacement of the corner $C$ per unit load.

**MPM.** The background mesh is the panel itself, meshed by gmsh with triangles of size $h$;
P1 velocity space, lumped mass, MUSL, standard (point) particles seeded 4 per triangle, each
with its sub-triangle's area: the particles integrate the P1 stiffness exactly, and their
weights on the loaded edge apply the traction as the finite element's consistent nodal load
(``fields["area"]``, :func:`fempm.boundary.consistent_load.consistent_weights`). The answer is
then the P1 finite element answer on the same mesh, first order in $h$ (docs/convergence.md).
The load is switched on at $t = 0$ and mass-proportional grid
damping at twice the estimated first eigenfrequency brings the panel to rest by
$t = 12 / \omega_1$; the load $F = 10^{-3}$ keeps the motion in the small-strain regime.
The corner displacement is a linear least-squares fit of the particles seeded in the triangle
at $C$, evaluated at $C$.

**Reference.** The same plane-strain problem solved by DOLFINx with Taylor-Hood $P_2/P_1$
displacement-pressure elements on gmsh triangles of size 0.5 (locking-free): $u_y(C) = 22.59$
for $\nu = 1/3$ (CoFEA's quadratic 3D results, 32.27 mm at $E = 70$, $F = 100$, scale to the
same 22.59) and $19.41$ for $\nu = 0.4999$.

Run: `.venv/bin/python demos/cooks_membrane.py [--h 6 4 3 2 1.5 1] [--nu 0.3333333 0.4999] [--out output/cook]`
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import fempm  # noqa: F401
from mpi4py import MPI

from fempm.scene import run
from fempm.scenes.cook import cook_membrane, corner_displacement, fe_reference
from fempm.studies.harness import Provenance


#: the small run its page in the docs shows, executed when the site is built (docs/demo_runs.py)
DOCS_RUN = ["--h", "6", "3", "--nu", "0.3333333333333333", "--fe-h", "1.0"]


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description="Cook's membrane: MPM vs FE")
    ap.add_argument("--h", type=float, nargs="+", default=[6.0, 4.0, 3.0, 2.0, 1.5, 1.0], help="mesh sizes")
    ap.add_argument("--nu", type=float, nargs="+", default=[1 / 3, 0.4999])
    ap.add_argument("--h-max-incompressible", type=float, default=2.0,
                    help="finest h run at nu > 0.49 (the wave speed, hence the step count, grows 33x)")
    ap.add_argument("--fe-h", type=float, default=0.5, help="mesh size of the FE reference")
    ap.add_argument("--degree", type=int, default=1)
    ap.add_argument("--variant", default=None, help="Lagrange variant of the velocity space (e.g. bernstein)")
    ap.add_argument("--mass", default="lumped", choices=["lumped", "consistent"])
    ap.add_argument("--domain", default="point")
    ap.add_argument("--out", type=Path, default=Path("output/cook"))
    ap.add_argument("--no-plot", action="store_true")
    a = ap.parse_args(argv)
    comm = MPI.COMM_WORLD
    rows = []
    for nu in a.nu:
        # The reference: Taylor-Hood P2/P1 on a fine mesh, per unit load.
        u_fe = fe_reference(nu, a.fe_h)
        for h in a.h:
            if nu > 0.49 and h < a.h_max_incompressible:
                continue
            scene = cook_membrane(h=h, nu=nu, degree=a.degree, variant=a.variant, mass=a.mass, domain=a.domain)
            t0 = time.perf_counter()
            summary = run(scene, None, progress=False)
            u = corner_displacement(scene.particles) / scene.params["load"]
            row = {"nu": nu, "h": h, "particles": scene.particles.num_global, "steps": summary["steps"],
                   "u_y": u[1], "u_x": u[0], "u_y_fe": u_fe[1], "rel_error": u[1] / u_fe[1] - 1.0,
                   "kinetic_end": summary["final"]["kinetic"], "wall_s": comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)}
            rows.append(row)
            if comm.rank == 0:
                print(f"nu = {nu:.4f}  h = {h:4.1f}  particles {row['particles']:6d}  steps {row['steps']:6d}  "
                      f"u_y(C) = {u[1]:8.4f}  FE {u_fe[1]:8.4f}  ({100 * row['rel_error']:+6.2f} %)  {row['wall_s']:.1f} s",
                      flush=True)
    if comm.rank == 0:
        a.out.mkdir(parents=True, exist_ok=True)
        Provenance.now(comm=MPI.COMM_SELF).write(a.out)
        with open(a.out / "cook.csv", "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
        if not a.no_plot:
            from fempm.io.plot import plot_curves

            curves, hlines = [], []
            for nu in a.nu:
                rs = [r for r in rows if r["nu"] == nu]
                curves.append(([r["h"] for r in rs], [r["u_y"] for r in rs], "o-", {"label": f"MPM, nu = {nu:.4g}"}))
                hlines.append((rs[0]["u_y_fe"], {"ls": "--", "color": "gray", "label": f"FE P2/P1, nu = {nu:.4g}"}))
            plot_curves(a.out / "cook.png", curves, hlines=hlines, xlabel="triangle size h",
                        ylabel="u_y(C) per unit load", title="Cook's membrane: MPM (P1, point particles) vs FE")
    return {"rows": rows}


if __name__ == "__main__":
    main()
