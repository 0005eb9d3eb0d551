"""Throughput of the explicit step: the two-disk scene (structured quadrilaterals) with lumped
mass, consistent mass (PETSc CG each step, partial lumping of the rims, consistent-mass
stable step) and consistent velocity mapping with lumped forces.

    python benchmarks/bench_step.py [--cells 80 160] [--t-end 0.15]

Prints a Markdown table: particles, steps, wall time, particle-steps per second and the wall
time per unit of simulated time (consistent mass takes smaller steps).
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import fempm  # noqa: F401
from mpi4py import MPI

from fempm.scene import run
from fempm.scenes import two_disks
from fempm.studies.harness import Provenance

VARIANTS = {
    "lumped": {"mass": "lumped"},
    "consistent": {"mass": "consistent"},
    "consistent (lumped forces)": {"mass": "consistent", "lumped_forces": True},
}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", type=int, nargs="+", default=[80, 160])
    ap.add_argument("--t-end", type=float, default=0.15)
    a = ap.parse_args(argv)
    comm = MPI.COMM_WORLD
    provenance = Provenance.now()
    rows = []
    run(two_disks(cells=8, t_end=0.01), None, progress=False)  # untimed: the compiled kernels load or compile
    for n in a.cells:
        for name, opts in VARIANTS.items():
            scene = two_disks(cells=n, t_end=a.t_end)
            scene.options = dataclasses.replace(scene.options, **opts)
            t0 = time.perf_counter()
            r = run(scene, None, progress=False)
            wall = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
            rows.append((f"{n}x{n} quads", r["particles"], name, r["steps"], wall,
                         r["particles"] * r["steps"] / wall, wall / a.t_end))
    if comm.rank == 0:
        print(f"{provenance.line()}\n\ntwo disks, t_end = {a.t_end}, {comm.size} rank(s)\n")
        print("| mesh | particles | mass | steps | wall [s] | particle-steps/s | wall per simulated second [s] |")
        print("|---|---|---|---|---|---|---|")
        for m, npart, name, steps, wall, rate, per in rows:
            print(f"| {m} | {npart} | {name} | {steps} | {wall:.2f} | {rate:.3g} | {per:.1f} |")


if __name__ == "__main__":
    main()
