r"""# A pressure pulse leaving through an absorbing boundary

The wave scene (`.venv/bin/python -m fempm run wave --boundary absorbing|fixed --cells N`,
`fempm.scenes.wave`): a cos^2 pulse of particle velocity with the stress of a wave running to
the right, in an elastic strip between frictionless walls (uniaxial strain: P wave), meets the
strip's end at x = L. The end is an absorbing boundary (`fempm.boundary.absorbing`: viscous
dashpots rho c_p, rho c_s on the grid, Lysmer and Kuhlemeyer 1969) or a fixed one. The run ends
when a reflected pulse would be back where the pulse started; `reflected_energy_ratio` is the
energy then in the strip over the pulse's energy.

The demo runs both ends at each resolution and writes `wave.csv` and `wave.md` (with the
command, commit and date), and with `--figure` the velocity along the strip at the end of
each run.

Run: `.venv/bin/python demos/wave.py [--cells 32 64 128 256] [--out docs/wave] [--figure]`
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

import fempm  # noqa: F401
from fempm.scene import run
from fempm.scenes.wave import BOUNDARIES, wave
from fempm.studies.harness import VENV_PYTHON, Provenance, write_table


def run_case(boundary: str, cells: int) -> tuple[dict, np.ndarray]:
    """One run: its row and the particles' (x, v_x) at the end (rank 0)."""
    scene = wave(cells=cells, boundary=boundary)
    t0 = time.perf_counter()
    s = run(scene, None, progress=False)
    p = scene.particles
    profile = np.concatenate(p.comm.allgather(np.stack([p.x[:, 0], p.fields["v"][:, 0]], axis=1)))
    return ({"boundary": boundary, "cells": cells, "reflected_energy_ratio": s["reflected_energy_ratio"],
             "energy_ratio": s["health"]["energy_ratio"], "steps": s["steps"], "wall_s": time.perf_counter() - t0},
            profile)


#: the table's columns: (row key, heading, format)
TABLE = [("boundary", "end", ""), ("cells", "cells", ""),
         ("reflected_energy_ratio", "reflected energy / pulse energy", ".4f"),
         ("energy_ratio", "energy / (initial + work)", ".4f"), ("steps", "steps", ""), ("wall_s", "wall (s)", ".2f")]


def figure(profiles: dict, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.2))
    for (boundary, cells), xv in profiles.items():
        order = np.argsort(xv[:, 0])
        ax.plot(xv[order, 0], xv[order, 1] * 1e3, ".", ms=1.5, label=f"{boundary}, {cells} cells")
    ax.set_xlabel("x")
    ax.set_ylabel("v_x at the end (x 1e-3; the pulse's amplitude 1)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "wave.png", dpi=120)
    plt.close(fig)


#: the small run its page in the docs shows, executed when the site is built (docs/demo_runs.py)
DOCS_RUN = ["--cells", "32", "64", "--figure"]


def main(argv: list[str] | None = None) -> list[dict]:
    ap = argparse.ArgumentParser(description="a pulse into an absorbing or a fixed end")
    ap.add_argument("--cells", type=int, nargs="+", default=[32, 64, 128, 256])
    ap.add_argument("--out", type=Path, default=Path("output/wave"))
    ap.add_argument("--figure", action="store_true")
    a = ap.parse_args(argv)
    provenance = Provenance.now(command=f"{VENV_PYTHON} demos/wave.py " + " ".join(argv if argv is not None else []))
    rows, profiles = [], {}
    for cells in a.cells:
        for boundary in BOUNDARIES:
            row, profiles[boundary, cells] = run_case(boundary, cells)
            rows.append(row)
            if MPI.COMM_WORLD.rank == 0:
                print(f"{boundary:9s} {cells:4d} cells: reflected {row['reflected_energy_ratio']:.4f}", flush=True)
                write_table(a.out, "wave", rows, provenance, TABLE)
    if a.figure and MPI.COMM_WORLD.rank == 0:
        figure(profiles, a.out)
    return rows


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
