r"""# A rigid strip footing pushed into a von Mises layer: Prandtl's bearing capacity

The footing scene (`.venv/bin/python -m fempm run footing --cells N --depth D`, `fempm.scenes.footing`):
a smooth rigid footing of width B (a box collider, `fempm.colliders`) pushed at a slow speed
into a weightless elastic-perfectly plastic von Mises layer 5B wide and 2B deep, plane strain.
Its mean contact pressure tends to Prandtl's limit $(2 + \pi) c$, $c = \sigma_y / \sqrt 3$.

The demo runs each resolution (cells across the footing) and writes `footing.csv` and
`footing.md` (command, commit, date): the bearing pressure at the end (the mean reaction over
the last tenth of the penetration) over Prandtl's, and with `--figure` the pressure against the
penetration (`footing.png`).

Run: `.venv/bin/python demos/footing.py [--cells 8 16 32] [--volumetric standard fbar] [--out docs/footing] [--figure]`
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

import fempm  # noqa: F401
from fempm.scene import run
from fempm.scenes.footing import footing
from fempm.studies.harness import VENV_PYTHON, Provenance, write_table

#: the table's columns: (row key, heading, format)
TABLE = [("cells", "cells across B", ""), ("volumetric", "volumetric", ""), ("bearing_pressure", "q (Pa)", ".0f"),
         ("prandtl", "(2 + pi) c (Pa)", ".0f"), ("bearing_ratio", "q / (2 + pi) c", ".4f"),
         ("error_percent", "error (%)", "+.2f"), ("steps", "steps", ""), ("wall_s", "wall (s)", ".0f")]


def run_case(cells: int, volumetric: str, depth: float) -> tuple[dict, np.ndarray]:
    """One run: its row and its curve (penetration / B, pressure / c) per step."""
    scene = footing(cells=cells, depth=depth)
    scene.options = dataclasses.replace(scene.options, volumetric=volumetric)
    t0 = time.perf_counter()
    s = run(scene, None, progress=False)
    c = scene.params["yield_stress"] / np.sqrt(3.0)
    return ({"cells": cells, "volumetric": volumetric, "bearing_pressure": s["bearing_pressure"],
             "prandtl": s["prandtl"], "bearing_ratio": s["bearing_ratio"],
             "error_percent": 100.0 * (s["bearing_ratio"] - 1.0), "steps": s["steps"],
             "wall_s": time.perf_counter() - t0},
            np.array(scene.watch.points) / [1.0, c])  # the scene's PressureCurve


def figure(curves: dict, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4))
    for (cells, volumetric), curve in curves.items():
        window = max(len(curve) // 100, 1)  # a moving mean over 1 % of the run: the step's reaction rings
        smooth = np.convolve(curve[:, 1], np.ones(window) / window, mode="valid")
        centre = np.convolve(curve[:, 0], np.ones(window) / window, mode="valid")
        ax.plot(centre, smooth, lw=1, label=f"{cells} cells across B, {volumetric}")
    ax.axhline(2.0 + np.pi, color="k", ls="--", lw=0.8, label="Prandtl, 2 + pi")
    ax.set_xlabel("penetration / B")
    ax.set_ylabel("mean contact pressure / c")
    ax.set_ylim(0.0, 1.5 * (2.0 + np.pi))
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "footing.png", dpi=120)
    plt.close(fig)


#: the small run its page in the docs shows, executed when the site is built (docs/demo_runs.py)
DOCS_RUN = ["--cells", "4", "--depth", "0.05", "--figure"]


def main(argv: list[str] | None = None) -> list[dict]:
    ap = argparse.ArgumentParser(description="a strip footing against Prandtl's bearing capacity")
    ap.add_argument("--cells", type=int, nargs="+", default=[8, 16, 32])
    ap.add_argument("--volumetric", nargs="+", default=["standard"], choices=["standard", "fbar"])
    ap.add_argument("--depth", type=float, default=0.1)
    ap.add_argument("--out", type=Path, default=Path("output/footing"))
    ap.add_argument("--figure", action="store_true")
    a = ap.parse_args(argv)
    provenance = Provenance.now(command=f"{VENV_PYTHON} demos/footing.py " + " ".join(argv if argv is not None else []))
    rows, curves = [], {}
    for volumetric in a.volumetric:
        for cells in a.cells:
            row, curves[cells, volumetric] = run_case(cells, volumetric, a.depth)
            rows.append(row)
            if MPI.COMM_WORLD.rank == 0:
                print(f"{cells:3d} cells, {volumetric}: q / (2 + pi) c = {row['bearing_ratio']:.4f}, "
                      f"{row['wall_s']:.0f} s", flush=True)
                write_table(a.out, "footing", rows, provenance, TABLE)
    if a.figure and MPI.COMM_WORLD.rank == 0:
        figure(curves, a.out)
    return rows


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
