r"""# A block and a disk on a frictional incline, against the rigid-body accelerations

The incline scene (`.venv/bin/python -m fempm run incline --body block|disk --angle DEG --friction MU`,
`fempm.scenes.incline`) at 30 degrees: the plane is the grid boundary $y = 0$ with Coulomb
friction, or a rigid body in frictional contact (`--plane rigid`), gravity rotated by the
slope; or (`--plane tagged`, the block) the tagged floor of a gmsh triangle mesh turned by the
slope, gravity vertical (`fempm.boundary.tagged`: the wall's normals from its facets). The analytic along-slope accelerations of the centre of mass:

* block: $g(\sin\theta - \mu\cos\theta)$ while $\mu < \tan\theta = 0.577$, 0 (it sticks) above;
* disk: $\tfrac23 g \sin\theta = 3.27$ m/s$^2$ (rolling without slip) for
  $\mu \ge \tan\theta / 3 = 0.192$, $g(\sin\theta - \mu\cos\theta)$ (sliding) below.

The demo runs each case at two resolutions (cells across the block's height or the disk's
radius) and writes `incline.csv` and `incline.md`: the measured acceleration (twice the
quadratic coefficient of a least-squares fit of the centre of mass over the second half of
the run), the analytic one, the error (relative, or against $g \sin\theta$ where the analytic
value is 0), the energy left over the work of gravity, and the wall time.

What it takes (see the scene's docstring): the disk has 4 x 4 particles per cell, and the
plane holds only the nodes the disk touches (its nodal centre of mass within half a cell of
the plane, `fempm.boundary.Friction` with a `gap`, and the contact's gap on the rigid plane)
and shares the normal impulse it takes over them by depth; the block has 30 % of PIC blended
in (the scene's default FLIP 0.7: with pure FLIP the frictional sliding of the elastic block
goes unstable and it slides up to twice too fast, and creeps where it should stick).

Run: `.venv/bin/python demos/incline.py [--cells 8 16] [--cases NAME ...] [--out docs/incline]`
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

import fempm  # noqa: F401
from fempm.scene import run
from fempm.scenes import incline
from fempm.studies.harness import VENV_PYTHON, Provenance, write_table

G_SIN = 9.81 * np.sin(np.radians(30.0))

#: name -> the scene's options (body, friction, plane), each with the scene's default PIC/FLIP
#: blend (0.7 for the block, pure FLIP for the disk)
#: the coefficients run for each plane and body
FRICTIONS = {("grid", "block"): (0.0, 0.2, 0.5, 0.6, 1.0), ("grid", "disk"): (0.0, 0.1, 0.2, 0.22, 0.25, 0.3, 1.0),
             ("rigid", "block"): (0.0, 0.2, 0.5, 0.6, 1.0), ("rigid", "disk"): (0.1, 0.2, 0.3),
             ("tagged", "block"): (0.0, 0.2, 0.5, 0.6, 0.7, 1.0), ("collider", "disk"): (0.1, 0.2, 0.22, 0.3, 1.0),
             ("collider on axes", "disk"): (0.1, 0.2, 0.22, 0.3, 1.0)}
#: how a case's name says its plane, and the scene's options for it
PLANES = {"grid": ("", {}), "rigid": ("rigid plane, ", {"plane": "rigid"}),
          "tagged": ("tagged wall, ", {"plane": "tagged"}), "collider": ("plane collider, ", {"plane": "collider"}),
          "collider on axes": ("plane collider on axis-aligned grid, ", {"plane": "collider", "turned": False})}
CASES = {f"{PLANES[plane][0]}{body} mu={mu:g}": dict(body=body, friction=mu, **PLANES[plane][1])
         for (plane, body), mus in FRICTIONS.items() for mu in mus}
#: the table's columns: (row key, heading, format)
TABLE = [("case", "case", ""), ("cells", "cells", ""), ("ppc", "ppc", ""),
         ("acceleration", "acceleration (m/s^2)", ".4f"),
         ("analytic", "analytic", ".4f"), ("error_percent", "error (%)", "+.2f"),
         ("energy_ratio", "energy / work", ".3f"), ("steps", "steps", ""), ("wall_s", "wall (s)", ".0f")]


def error_percent(acceleration: float, analytic: float) -> float:
    """The relative error in percent; against g sin(theta) where the analytic value is 0."""
    return 100.0 * (acceleration - analytic) / (analytic if analytic != 0.0 else G_SIN)


def run_case(name: str, cells: int, t_end: float | None = None) -> dict:
    scene = incline(angle=30.0, cells=cells, frames=0, t_end=t_end, **CASES[name])
    t0 = time.perf_counter()
    s = run(scene, None, progress=False)
    return {"case": name, "cells": cells, "ppc": scene.params["ppc"], "acceleration": s["acceleration"],
            "analytic": s["analytic"], "error_percent": error_percent(s["acceleration"], s["analytic"]),
            "energy_ratio": s["health"]["energy_ratio"], "steps": s["steps"], "wall_s": time.perf_counter() - t0}


#: the small run its page in the docs shows, executed when the site is built (docs/demo_runs.py)
DOCS_RUN = ["--cells", "4", "--cases", "block mu=0.2", "disk mu=0.3", "--t-end", "0.2"]


def main(argv: list[str] | None = None) -> list[dict]:
    ap = argparse.ArgumentParser(description="the incline against the rigid-body accelerations")
    ap.add_argument("--cells", type=int, nargs="+", default=[8, 16])
    ap.add_argument("--cases", nargs="+", default=list(CASES), metavar="NAME")
    ap.add_argument("--t-end", type=float, default=None, help="shorter runs (tests)")
    ap.add_argument("--out", type=Path, default=Path("output/incline"))
    a = ap.parse_args(argv)
    unknown = [c for c in a.cases if c not in CASES]
    if unknown:
        raise ValueError(f"unknown case(s) {unknown}; expected some of {list(CASES)}")
    provenance = Provenance.now(command=f"{VENV_PYTHON} demos/incline.py " + " ".join(argv if argv is not None else []))
    rows = []
    for name in a.cases:
        for cells in a.cells:
            rows.append(run_case(name, cells, a.t_end))
            if MPI.COMM_WORLD.rank == 0:
                r = rows[-1]
                print(f"{name:28s} {cells:3d} cells: {r['acceleration']:.4f} against {r['analytic']:.4f} "
                      f"({r['error_percent']:+.2f} %), {r['wall_s']:.0f} s", flush=True)
                write_table(a.out, "incline", rows, provenance, TABLE)
    return rows


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
