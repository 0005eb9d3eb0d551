r"""# Granular column collapse

A column of cohesionless sand, $L_0 = 0.2$ m wide and $H_0 = a L_0$ high, stands against a
smooth wall on a rough floor and is released at $t = 0$ (`fempm.scenes.column_collapse`):
plane strain, Drucker-Prager matched to Mohr-Coulomb in plane strain with friction angle
$\phi = 30°$, no cohesion, no dilatancy ($\psi = 0$), $E = 5$ MPa, $\nu = 0.3$,
$\rho = 2000$ kg/m$^3$; the floor has Coulomb friction $\mu = 0.5$; the column starts under its
geostatic stress with $K_0 = 1 - \sin\phi$. The run lasts $6\sqrt{H_0/g}$, twice the time the
collapse takes; the deposit is then at rest (its kinetic energy is given as a fraction of the
potential energy released).

The measures are those of the experiments on two-dimensional columns (Lube et al. 2005,
Lajeunesse et al. 2005): the runout $(L_\infty - L_0)/L_0$ and the final height
$H_\infty/L_0$. Both grow linearly with $a$ for short columns (whose top does not move:
$H_\infty = H_0$) and more slowly for tall ones, where the experiments find the runout
$\propto a^{2/3}$:

| experiments | short columns | tall columns |
|---|---|---|
| Lube, Huppert, Sparks & Freundt 2005 (Phys. Rev. E 72, 041301) | $1.2\,a$, $a < 1.8$ | $1.9\,a^{2/3}$, $a > 2.8$ |
| Lajeunesse, Monnier & Homsy 2005 (Phys. Fluids 17, 103302) | $1.8\,a$, $a \lesssim 3$ | $2.3\,a^{2/3}$, $a \gtrsim 3$ |

(coefficients as Lagrée, Staron & Popinet 2011, J. Fluid Mech. 686, eqs. 3.1-3.2, quote them;
`fempm.scenes.column.RUNOUT_LAWS`). The two sets of experiments differ by up to 50 %, which is
the spread a continuum model can be held to. The demo runs the aspect ratios 0.5, 1, 2 and 4,
prints the table with both laws (a range where $a$ lies between a law's two branches), fits the
exponent of the runout between consecutive aspect ratios, and draws the deposits and the
runout against $a$ with the laws.

Run: `.venv/bin/python demos/column_collapse.py [--cells 16] [--aspects 0.5 1 2 4] [--out output/column_collapse]`
"""

from __future__ import annotations

import argparse
from pathlib import Path

import fempm  # noqa: F401
import numpy as np
from mpi4py import MPI

from fempm.scene import run, run_stats
from fempm.scenes import column_collapse
from fempm.scenes.column import RUNOUT_LAWS, published_runout
from fempm.studies.harness import Provenance


#: the small run its page in the docs shows, executed when the site is built (docs/demo_runs.py)
DOCS_RUN = ["--cells", "4", "--aspects", "0.5", "2"]


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description="granular column collapse at several aspect ratios")
    ap.add_argument("--cells", type=int, default=16, help="cells across the column width")
    ap.add_argument("--aspects", type=float, nargs="+", default=[0.5, 1.0, 2.0, 4.0])
    ap.add_argument("--out", type=Path, default=Path("output/column_collapse"))
    ap.add_argument("--no-plot", action="store_true")
    a = ap.parse_args(argv)
    comm = MPI.COMM_WORLD
    rows, deposits = [], []
    for aspect in a.aspects:
        scene = column_collapse(aspect=aspect, cells=a.cells)
        res = run(scene, a.out / f"a{aspect:g}", progress=False)
        p = scene.particles
        x = np.concatenate(comm.allgather(p.x)) / scene.params["width"]
        deposits.append((aspect, x))
        rows.append({"aspect": aspect, "runout": res["runout"], "final_height": res["final_height"],
                     "kinetic_fraction": res["kinetic_fraction"], **run_stats(res)})
    aspects = np.array([r["aspect"] for r in rows])
    runout = np.array([r["runout"] for r in rows])
    exponents = np.diff(np.log(runout)) / np.diff(np.log(aspects)) if len(rows) > 1 else np.zeros(0)
    if comm.rank == 0:
        a.out.mkdir(parents=True, exist_ok=True)
        provenance = Provenance.now(comm=MPI.COMM_SELF)
        provenance.write(a.out)
        lines = [f"Granular column collapse, {a.cells} cells across the column width", "", provenance.line(), "",
                 "| a | (L_inf - L0)/L0 | " + " | ".join(RUNOUT_LAWS) + " | H_inf/L0 | kinetic / released energy "
                 "| particles | steps |",
                 "|---|---|" + "---|" * len(RUNOUT_LAWS) + "---|---|---|---|"]

        def law(lo: float, hi: float) -> str:
            return f"{lo:.2f}" if hi - lo < 1e-12 else f"{lo:.2f}-{hi:.2f}"

        lines += [f"| {r['aspect']:g} | {r['runout']:.3f} | "
                  + " | ".join(law(*v) for v in published_runout(r["aspect"]).values())
                  + f" | {r['final_height']:.3f} | {r['kinetic_fraction']:.1e} | {r['particles']} | {r['steps']} |"
                  for r in rows]
        lines += ["", "Runout exponent between consecutive aspect ratios: " +
                  ", ".join(f"{lo:g}-{hi:g}: {e:.2f}" for lo, hi, e in zip(aspects[:-1], aspects[1:], exponents))]
        (a.out / "column_collapse.md").write_text("\n".join(lines) + "\n")
        print("\n".join(lines))
        if not a.no_plot:
            import matplotlib

            matplotlib.use("Agg")
            import matplotlib.pyplot as plt

            fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4), gridspec_kw={"width_ratios": [2, 1]})
            for aspect, x in sorted(deposits, key=lambda d: -d[0]):  # the tall ones first, under the others
                left.scatter(x[:, 0], x[:, 1], s=1, label=f"a = {aspect:g}")
            left.set(xlabel="$x/L_0$", ylabel="$y/L_0$", title="final deposits", aspect="equal")
            left.legend(markerscale=8)
            right.loglog(aspects, runout, "o-", label="fempm")
            fine = np.geomspace(min(aspects.min(), 0.5), max(aspects.max(), 4.0), 60)
            for (name, (c1, a1, c2, a2)), style in zip(RUNOUT_LAWS.items(), ("k", "0.5")):
                short, tall = fine[fine <= a1], fine[fine >= a2]
                right.loglog(short, c1 * short, "--", color=style, lw=0.9, label=f"{name}: ${c1:g}\\,a$")
                right.loglog(tall, c2 * tall ** (2 / 3), ":", color=style, lw=1.2,
                             label=f"{name}: ${c2:g}\\,a^{{2/3}}$")
            right.set(xlabel="aspect ratio $a$", ylabel=r"$(L_\infty - L_0)/L_0$", title="runout")
            right.legend(fontsize=7)
            fig.tight_layout()
            fig.savefig(a.out / "column_collapse.png", dpi=120)
            plt.close(fig)
    return {"rows": rows, "exponents": exponents.tolist()}


if __name__ == "__main__":
    main()
