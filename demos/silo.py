r"""# Granular flow out of a hopper onto a floor

The silo scene (`.venv/bin/python -m fempm run silo --cells N`, `fempm.scenes.silo`): a wedge hopper with
gmsh-tagged frictional walls (`fempm.boundary.tagged`) drains a cohesionless granular fill (the
mu(I) rheology, or Drucker-Prager with `--law dp`) through its outlet onto a floor, from whose
edges the material spills out of the mesh and is removed (`outside="remove"`). The demo runs
each resolution (cells across the outlet) and each outlet width, and writes `silo.csv` and
`silo.md` (command, commit, date): the steady discharge rate, Beverloo's coefficient, what left
the mesh, and the mass balance (particles + removed - fill); with several outlets the exponent
of the discharge in the outlet width, fitted at each number of cells across the outlet (or at
one cell size, `--h`; Beverloo: 3/2); with
`--figure` the flow at three times and the hopper's mass against time (`silo.png`).

Run: `.venv/bin/python demos/silo.py [--cells 5 10] [--outlets 0.1] [--h H] [--fill 0.3] [--width 0.5] [--no-floor]
[--law mu-i|dp] [--t-end 1.0 ...] [--out docs/silo] [--figure]`
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

import fempm  # noqa: F401
from fempm.scene import run
from fempm.scenes.silo import LAWS, WINDOW, silo
from fempm.studies.harness import VENV_PYTHON, Provenance, write_table

#: the table's columns: (row key, heading, format)
TABLE = [("law", "law", ""), ("outlet", "outlet D (m)", ".3g"), ("cells", "cells across the outlet", ""),
         ("discharge_rate", "discharge (kg/s per m)", ".2f"), ("beverloo", "Beverloo C", ".3f"),
         ("removed_mass", "removed (kg)", ".3f"), ("hopper_mass", "left in the hopper (kg)", ".3f"),
         ("fill", "fill (kg)", ".3f"), ("balance", "(particles + removed - fill) / fill", ".1e"),
         ("steps", "steps", ""), ("wall_s", "wall (s)", ".0f")]
#: the times of the figure's snapshots, as fractions of the run
SNAPSHOTS = (0.15, 0.5, 1.0)


def run_case(cells: int, t_end: float, outlet: float = 0.1, fill: float = 0.3, law: str = "mu-i",
             width: float = 0.5, floor: bool = True) -> tuple[dict, dict]:
    """One run: its row, and for the figure the snapshots (t -> (x, speed)) and the hopper's mass
    (the scene's :class:`~fempm.scenes.silo.HopperMass`)."""
    scene = silo(cells=cells, t_end=t_end, frames=0, outlet=outlet, fill=fill, law=law, width=width, floor=floor)
    p = scene.particles
    fill = p.comm.allreduce(float(p.mass.sum()))
    shots = {}
    wanted = list(SNAPSHOTS)

    def record(solver):
        if wanted and solver.t >= wanted[0] * t_end * (1 - 1e-9):
            wanted.pop(0)
            x = np.concatenate(p.comm.allgather(p.x[:, :2]))
            speed = np.concatenate(p.comm.allgather(np.linalg.norm(p.fields["v"], axis=1)))
            shots[solver.t] = (x, speed)

    t0 = time.perf_counter()
    s = run(scene, None, progress=False, callback=record)
    left = p.comm.allreduce(float(p.mass.sum()))
    row = {"law": law, "outlet": outlet, "cells": cells, "discharge_rate": s["discharge_rate"],
           "beverloo": s["beverloo_coefficient"], "removed_mass": s["removed"]["mass"],
           "hopper_mass": s["hopper_mass"], "fill": fill, "balance": (left + s["removed"]["mass"] - fill) / fill,
           "steps": s["steps"], "wall_s": time.perf_counter() - t0}
    return row, {"shots": shots, "history": np.array(scene.watch.points), "outline": scene.mesh.geometry.x[:, :2]}


def figure(cases: dict, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cells = max(cases)
    case = cases[cells]
    fig, axes = plt.subplots(1, len(case["shots"]) + 1, figsize=(4.0 * (len(case["shots"]) + 1), 3.6))
    lo, hi = case["outline"].min(axis=0), case["outline"].max(axis=0)
    for ax, (t, (x, speed)) in zip(axes, sorted(case["shots"].items())):
        sc = ax.scatter(x[:, 0], x[:, 1], c=speed, s=1.0, cmap="viridis", vmin=0.0, vmax=2.0)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect("equal")
        ax.set_title(f"t = {t:.2f} s ({cells} cells across the outlet)", fontsize=9)
    fig.colorbar(sc, ax=axes[-2], label="speed (m/s)", shrink=0.8)
    ax = axes[-1]
    for c, data in sorted(cases.items()):
        t, m = data["history"].T
        ax.plot(t, m, lw=1, label=f"{c} cells")
    ax.axhspan(WINDOW[1] * case["history"][0, 1], WINDOW[0] * case["history"][0, 1], color="0.9",
               label="steady window")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("mass in the hopper (kg per m)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "silo.png", dpi=120)
    plt.close(fig)


#: the small run its page in the docs shows, executed when the site is built (docs/demo_runs.py)
DOCS_RUN = ["--cells", "3", "--t-end", "0.5", "--figure"]


def main(argv: list[str] | None = None) -> list[dict]:
    ap = argparse.ArgumentParser(description="granular discharge from a hopper")
    ap.add_argument("--cells", type=int, nargs="+", default=[5, 10])
    ap.add_argument("--outlets", type=float, nargs="+", default=[0.1], help="outlet widths D (m)")
    ap.add_argument("--h", type=float, default=None,
                    help="one cell size for every outlet (cells = D / h) instead of --cells")
    ap.add_argument("--fill", type=float, default=0.3, help="the fill's height above the outlet (m)")
    ap.add_argument("--law", choices=LAWS, default="mu-i")
    ap.add_argument("--width", type=float, default=0.5, help="the hopper's top width (m)")
    ap.add_argument("--no-floor", action="store_true",
                    help="no floor: the grains fall out of the mesh (no heap chokes the outlet)")
    ap.add_argument("--t-end", type=float, nargs="+", default=[1.0],
                    help="the run's length: one for every outlet, or one per outlet (without a floor, before the "
                         "hopper is empty)")
    ap.add_argument("--out", type=Path, default=Path("output/silo"))
    ap.add_argument("--figure", action="store_true")
    a = ap.parse_args(argv)
    provenance = Provenance.now(command=f"{VENV_PYTHON} demos/silo.py " + " ".join(argv if argv is not None else []))
    rows, cases = [], {}
    if len(a.t_end) not in (1, len(a.outlets)):
        ap.error(f"--t-end takes one value or one per outlet ({len(a.outlets)})")
    for k, outlet in enumerate(a.outlets):
        t_end = a.t_end[k if len(a.t_end) > 1 else 0]
        for cells in ([int(round(outlet / a.h))] if a.h else a.cells):
            row, case = run_case(cells, t_end, outlet, a.fill, a.law, a.width, not a.no_floor)
            if outlet == a.outlets[0]:
                cases[cells] = case
            rows.append(row)
            if MPI.COMM_WORLD.rank == 0:
                print(f"D = {outlet:g}, {cells:3d} cells: discharge {row['discharge_rate']:.2f} kg/s "
                      f"(Beverloo C {row['beverloo']:.3f}), removed {row['removed_mass']:.3f} kg, "
                      f"balance {row['balance']:.1e}, {row['wall_s']:.0f} s", flush=True)
                write_table(a.out, "silo", rows, provenance, TABLE)
    if len(a.outlets) > 1 and MPI.COMM_WORLD.rank == 0:
        for cells in sorted({r["cells"] for r in rows}) if not a.h else [None]:
            same = [r for r in rows if cells is None or r["cells"] == cells]
            if len(same) > 1:
                exponent = np.polyfit(np.log([r["outlet"] for r in same]),
                                      np.log([r["discharge_rate"] for r in same]), 1)[0]
                at = f"h = {a.h:g}" if a.h else f"{cells} cells across each outlet"
                print(f"discharge ~ D^{exponent:.3f} at {at} (Beverloo: D^1.5)")
    if a.figure and MPI.COMM_WORLD.rank == 0:
        figure(cases, a.out)
    return rows


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
