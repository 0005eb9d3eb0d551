"""The figures of docs/implicit.md: implicit against explicit runs of Cook's membrane and of the
vibrating bar, and F-bar on Cook's membrane near incompressibility.

    python benchmarks/implicit_figures.py [--cook 2 1] [--bar] [--fbar 2] [--fbar-implicit 4 2 1] [--disks] [--compaction]
                                          [--p2 4 2 1]

* ``--cook H ...``: Cook's membrane (nu = 1/3, E = 1, load 1e-3), at each triangle size H: the
  scene's explicit damped run and quasi-static implicit runs in 1 and 10 load steps; the
  vertical displacement of C per unit load against the Taylor-Hood reference 22.611, and the
  wall time of each run (``fempm.scene.run``, no output);
* ``--bar``: the vibrating bar (16 cells, 2 particles a cell), the explicit run at CFL 0.4 and
  Newmark's method (beta = 1/4, gamma = 1/2) at a Courant number of 4, over two periods: the
  period measured from the zero crossings of the centre-of-mass velocity against the exact
  :math:`2\\pi/\\omega`, the largest error of that velocity over the amplitude, the energy at the
  end over the initial one;
* ``--fbar H ...``: Cook's membrane at nu = 0.4999 (P1 triangles of size H), the explicit damped
  run with and without F-bar, against the Taylor-Hood reference 19.429;
* ``--fbar-implicit H ...``: the same, quasi-static implicit in 1 and 10 load steps with F-bar
  and in 1 without;
* ``--disks``: the scene ``disks`` at nu = 0.4999 (20 cells, t_end = 3, its ``LinearElastic``,
  MUSL, lumped mass, point particles, FLIP) with and without F-bar: outcome, E/E0, steps;
* ``--compaction``: the scene ``compaction`` (5 quasi-static steps) at 4, 8, 16 and 32 cells over
  the height with point particles, uGIMP, cpGIMP, CPDI1 and CPDI2: ``stress_error`` and the rate
  fitted to it;
* ``--p2 H ...``: degree 2 in the implicit step: the column of ``tests/implicit/test_implicit_p2.py``
  (unit square or cube, slip sides, fixed base, gravity; 2, 4, 8 cells; 3 and 4 in 3D) on every
  cell type, P1 lumped, P2 Lagrange consistent and Bernstein P2 lumped (simplices), the relative
  L2 error of u_y against the exact uniaxial strain and its fitted rate; Cook's membrane at
  each H in one quasi-static step, P1, P2 Lagrange consistent, Bernstein P2 lumped, against the
  reference; and Cook's explicit damped run (the scene's defaults, CFL 0.4) with P2 Lagrange
  consistent and Bernstein P2 lumped mass.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

import fempm
from fempm.scenes.bar import vibrating_bar
from fempm.scenes.cook import FE_REFERENCE, cook_membrane
from fempm.stepping import StepOptions

REFERENCE = FE_REFERENCE  # Taylor-Hood P2-P4 extrapolated (fempm.scenes.cook.FE_REFERENCE)
COOK_HEADER = ("| h | nu | run | steps | u_y(C) per unit load | against the reference | wall (s) |\n"
               "|---|---|---|---|---|---|---|")


def timed_run(scene) -> tuple[dict, float]:
    t0 = time.perf_counter()
    out = fempm.scene.run(scene, None, progress=False)
    return out, time.perf_counter() - t0


def cook_row(h: float, nu: float, label: str, change) -> str:
    scene = cook_membrane(h=h, nu=nu, load=1e-3, frames=0)
    change(scene)
    out, wall = timed_run(scene)
    uy = out["corner_displacement"][1] / 1e-3
    error = 100 * (uy / REFERENCE[nu] - 1)
    return f"| {h:g} | {nu:g} | {label} | {out['steps']} | {uy:.3f} | {error:+.2f} % | {wall:.3f} |"


def implicit(steps: int, volumetric: str = "standard"):
    def change(scene):
        scene.options = StepOptions(integrator="implicit", dynamics="quasi-static", load_ramp=scene.t_end,
                                    volumetric=volumetric)
        scene.dt = scene.t_end / steps
    return change


def fbar(volumetric: str):
    def change(scene):
        scene.options = dataclasses.replace(scene.options, volumetric=volumetric)
    return change


def bar_row(label: str, options: StepOptions, courant: float) -> str:
    scene = vibrating_bar(cells=16, ppc=2)
    pr = scene.params
    s = dataclasses.replace(scene, options=options).solver()
    dt = courant * (pr["L"] / pr["cells"]) / np.sqrt(pr["E"] / pr["rho"])
    omega, amplitude = pr["omega"], pr["v0"] / (pr["beta"] * pr["L"])
    period = 2 * np.pi / omega
    p = s.particles
    e0 = s.energies()["total"]
    t0 = time.perf_counter()
    ts, vs = [0.0], [amplitude]
    while s.t < 2 * period - 1e-9 * period:
        s.step(min(dt, 2 * period - s.t))
        ts.append(s.t)
        vs.append(p.comm.allreduce(float(p.mass @ p.fields["v"][:, 0])) / p.comm.allreduce(float(p.mass.sum())))
    wall = time.perf_counter() - t0
    ts, vs = np.array(ts), np.array(vs)
    worst = np.abs(vs - amplitude * np.cos(omega * ts)).max() / amplitude
    k = np.flatnonzero(np.sign(vs[1:]) != np.sign(vs[:-1]))  # zero crossings, linearly interpolated
    zeros = ts[k] - vs[k] * (ts[k + 1] - ts[k]) / (vs[k + 1] - vs[k])
    measured = 2 * np.mean(np.diff(zeros)) if len(zeros) > 1 else np.nan
    energy = s.energies()["total"] / e0
    return (f"| {label} | {courant:g} | {len(ts) - 1} | {measured:.4f} | {period:.4f} | "
            f"{100 * (measured / period - 1):+.2f} % | {worst:.3f} | {energy:.4f} | {wall:.3f} |")


def disks_rows() -> None:
    from fempm.scenes import two_disks

    print("| volumetric | outcome | E/E0 | steps | wall (s) |\n|---|---|---|---|---|")
    for volumetric in ("standard", "fbar"):
        scene = two_disks(cells=20, t_end=3.0, nu=0.4999, frames=0)
        fbar(volumetric)(scene)
        t0 = time.perf_counter()
        try:
            out = fempm.scene.run(scene, None, progress=False)
            outcome, ratio, steps = "reached t_end", out["health"]["energy_ratio"], out["steps"]
        except fempm.SimulationError as e:
            outcome, ratio, steps = f"stopped: {str(e)[:60]}", e.health["energy_ratio"], e.health["steps"]
        print(f"| {volumetric} | {outcome} | {ratio:.3f} | {steps} | {time.perf_counter() - t0:.1f} |")


def compaction_rows() -> None:
    from fempm.scenes.compaction import compaction

    sizes = (4, 8, 16, 32)
    print("| domain | " + " | ".join(f"{n} cells" for n in sizes) + " | fitted rate | wall (s) |")
    print("|---|" + "---|" * (len(sizes) + 2))
    for domain in ("point", "ugimp", "cpgimp", "cpdi1", "cpdi2"):
        errors, t0 = [], time.perf_counter()
        for n in sizes:
            errors.append(fempm.scene.run(compaction(cells=n, domain=domain, frames=0), None,
                                          progress=False)["stress_error"])
        rate = -np.polyfit(np.log(sizes), np.log(errors), 1)[0]
        print(f"| {domain} | " + " | ".join(f"{e:.3e}" for e in errors)
              + f" | {rate:.2f} | {time.perf_counter() - t0:.2f} |")


def p2_rows(sizes: list[float]) -> None:
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "implicit"))
    from test_implicit_p2 import column, column_error

    spaces = [("P1 lumped", 1, "equispaced", "lumped"), ("P2 Lagrange consistent", 2, "equispaced", "consistent"),
              ("Bernstein P2 lumped", 2, "bernstein", "lumped")]
    print("| cell | space | errors (cells: error) | fitted rate |\n|---|---|---|---|")
    for cell, ns in (("triangle", (2, 4, 8)), ("quadrilateral", (2, 4, 8)), ("tetrahedron", (2, 3, 4)),
                     ("hexahedron", (2, 3, 4))):
        for label, degree, variant, mass in spaces:
            if variant == "bernstein" and cell in ("quadrilateral", "hexahedron"):
                continue  # (basix: Bernstein on simplices)
            errors = []
            for n in ns:
                s = column(cell, n, degree, variant, mass)
                s.step(1.0)
                errors.append(column_error(s))
            rate = -np.polyfit(np.log(ns), np.log(errors), 1)[0]
            print(f"| {cell} | {label} | " + ", ".join(f"{n}: {e:.2e}" for n, e in zip(ns, errors))
                  + f" | {rate:.2f} |")
    print(COOK_HEADER)
    for h in sizes:
        for label, degree, variant, mass in spaces:
            def change(scene, degree=degree, variant=variant, mass=mass):
                built = cook_membrane(h=scene.params["h"], nu=1 / 3, load=1e-3, frames=0, degree=degree,
                                      variant=None if variant == "equispaced" else variant, mass=mass)
                scene.__dict__.update(built.__dict__)
                implicit(1)(scene)
                scene.options = dataclasses.replace(scene.options, mass=mass)
            print(cook_row(h, 1 / 3, f"implicit, quasi-static, 1 step, {label}", change))
    for h in sizes:
        for label, variant, mass in (("P2 Lagrange consistent", None, "consistent"),
                                     ("Bernstein P2 lumped", "bernstein", "lumped")):
            def change(scene, variant=variant, mass=mass):
                built = cook_membrane(h=scene.params["h"], nu=1 / 3, load=1e-3, frames=0, degree=2, variant=variant,
                                      mass=mass)
                scene.__dict__.update(built.__dict__)
            print(cook_row(h, 1 / 3, f"explicit, damped, {label}", change))


def main() -> None:
    a = argparse.ArgumentParser()
    a.add_argument("--cook", type=float, nargs="*", default=[])
    a.add_argument("--bar", action="store_true")
    a.add_argument("--fbar", type=float, nargs="*", default=[])
    a.add_argument("--fbar-implicit", type=float, nargs="*", default=[])
    a.add_argument("--disks", action="store_true")
    a.add_argument("--compaction", action="store_true")
    a.add_argument("--p2", type=float, nargs="*", default=[])
    args = a.parse_args()
    if args.cook:
        print(COOK_HEADER)
        for h in args.cook:
            print(cook_row(h, 1 / 3, "explicit, damped", lambda scene: None))
            print(cook_row(h, 1 / 3, "implicit, quasi-static, 1 step", implicit(1)))
            print(cook_row(h, 1 / 3, "implicit, quasi-static, 10 steps", implicit(10)))
    if args.bar:
        print("| run | Courant | steps | period | exact | period error | max v_cm error / amplitude | E(end) / E(0) "
              "| wall (s) |\n|---|---|---|---|---|---|---|---|---|")
        print(bar_row("explicit, MUSL, lumped", StepOptions(), 0.4))
        print(bar_row("implicit, Newmark, lumped", StepOptions(integrator="implicit"), 4.0))
        print(bar_row("implicit, Newmark, consistent", StepOptions(integrator="implicit", mass="consistent"), 4.0))
    if args.fbar:
        print(COOK_HEADER)
        for h in args.fbar:
            print(cook_row(h, 0.4999, "explicit, damped, F-bar", fbar("fbar")))
            print(cook_row(h, 0.4999, "explicit, damped, standard", fbar("standard")))
    if args.fbar_implicit:
        print(COOK_HEADER)
        for h in args.fbar_implicit:
            for steps in (1, 10):
                print(cook_row(h, 0.4999, f"implicit, quasi-static, {steps} step(s), F-bar", implicit(steps, "fbar")))
            print(cook_row(h, 0.4999, "implicit, quasi-static, 1 step(s), standard", implicit(1)))


    if args.disks:
        disks_rows()
    if args.compaction:
        compaction_rows()
    if args.p2:
        p2_rows(args.p2)


if __name__ == "__main__":
    main()
