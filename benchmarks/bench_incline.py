"""Time a step of the incline scene (`fempm.scenes.incline`): the compiled step against the
generic one, on the disk whose plane holds only the nodes it touches (a friction wall with a
position check) and whose hypoelastic law runs in `fempm.kernels.plasticity`.

Run: `python benchmarks/bench_incline.py [--cells 16] [--body disk] [--steps 200]`.
"""

from __future__ import annotations

import argparse
import time

import fempm  # noqa: F401  (DOLFINx set-up before the scene imports)
from mpi4py import MPI

from fempm.scenes.incline import incline
from fempm.studies.harness import Provenance


def time_steps(compiled: bool, body: str, cells: int, steps: int, warm: int = 20) -> tuple[float, int]:
    """(seconds per step after ``warm`` steps, particles) of the incline at mu = 0.2."""
    solver = incline(body=body, friction=0.2, cells=cells).solver()
    solver.compiled = compiled
    for _ in range(warm):
        solver.step()
    MPI.COMM_WORLD.Barrier()
    t0 = time.perf_counter()
    for _ in range(steps):
        solver.step()
    MPI.COMM_WORLD.Barrier()
    return (time.perf_counter() - t0) / steps, MPI.COMM_WORLD.allreduce(len(solver.particles))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", type=int, default=16)
    ap.add_argument("--body", choices=("block", "disk"), default="disk")
    ap.add_argument("--steps", type=int, default=200)
    a = ap.parse_args(argv)
    provenance = Provenance.now()
    if MPI.COMM_WORLD.rank == 0:
        print(provenance.line(), flush=True)
    for compiled in (False, True):
        t, n = time_steps(compiled, a.body, a.cells, a.steps)
        if MPI.COMM_WORLD.rank == 0:
            print(f"{a.body}, {a.cells} cells, {n} particles, {'compiled' if compiled else 'generic'} step: "
                  f"{1e3 * t:.1f} ms a step", flush=True)


if __name__ == "__main__":
    main()
