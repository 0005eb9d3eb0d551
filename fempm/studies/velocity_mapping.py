r"""The velocity round trip of each transfer with each mass (part of ``python -m fempm study
mapping``): what one P2G then G2P, with no force, does to a particle velocity field.

The particles (jittered, as in :mod:`fempm.studies.mapping`) carry a rigid rotation plus a
vortex,

.. math::
    v(x) = \omega \times (x - c) + \big(-\sin^2(\pi x) \sin(2 \pi y),\ \sin(2 \pi x) \sin^2(\pi y)\big),
    \qquad \omega = 1,\ c = (\tfrac12, \tfrac12),

and APIC and TPIC particles its exact gradient (:meth:`fempm.stepping.Solver.set_velocity_gradient`).
One step of a stress-free body with no load and a step of :math:`10^{-12}` maps them to the
grid and back; the error is the mass-weighted relative change
:math:`\big(\sum_p M_p |v_p^+ - v_p|^2 / \sum_p M_p |v_p|^2\big)^{1/2}` and the time the step's.
FLIP keeps the particle velocity by construction (its round trip adds the grid's change, here
none); PIC, XPIC(m), APIC and TPIC replace it by what the grid holds.
"""

from __future__ import annotations

import csv
import itertools
import time
from pathlib import Path

import dolfinx.fem
import numpy as np
from mpi4py import MPI

from fempm.materials.linear_elastic import LinearElastic
from fempm.particles.seeding import create_particles
from fempm.stepping.options import StepOptions
from fempm.stepping.solver import Solver
from fempm.studies.convergence import Config

__all__ = ["COLUMNS", "MASSES", "TRANSFERS", "rates", "round_trip", "run", "velocity", "write"]

TRANSFERS = ("flip", "pic", "xpic2", "xpic5", "apic", "tpic")
MASSES = ("lumped", "fmpm3", "consistent")
COLUMNS = ["mesh", "n", "h", "ppc", "transfer", "mass", "error", "time_s"]


def velocity(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The field (n, 2) and its gradient (n, 2, 2) at the points ``x`` (n, 2) (see the module)."""
    X, Y = x[:, 0], x[:, 1]
    pi = np.pi
    v = np.stack([-(Y - 0.5) - np.sin(pi * X) ** 2 * np.sin(2 * pi * Y),
                  (X - 0.5) + np.sin(2 * pi * X) * np.sin(pi * Y) ** 2], axis=1)
    g = np.empty((len(x), 2, 2))
    g[:, 0, 0] = -pi * np.sin(2 * pi * X) * np.sin(2 * pi * Y)
    g[:, 0, 1] = -1.0 - 2 * pi * np.sin(pi * X) ** 2 * np.cos(2 * pi * Y)
    g[:, 1, 0] = 1.0 + 2 * pi * np.cos(2 * pi * X) * np.sin(pi * Y) ** 2
    g[:, 1, 1] = pi * np.sin(2 * pi * X) * np.sin(2 * pi * Y)
    return v, g


def round_trip(mesh, ppc: int, transfer: str, mass: str, *, seed: int = 1) -> dict:
    """One round trip (see the module) on ``mesh``: its error and time. Collective."""
    comm = mesh.comm
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    p = create_particles(mesh, ppc, jitter=0.5, seed=seed)
    v0, grad = velocity(p.x)
    p.fields["v"] = v0.copy()
    options = StepOptions(scheme="USL", mass=mass, **Config(transfer=transfer).transfer_options)
    solver = Solver(V, p, [LinearElastic(1.0, 0.3)], options=options)
    solver.set_velocity_gradient(grad)
    v0 = p.fields["v"].copy()  # (the same order as after the step: no particle moves cell in 1e-12)
    comm.Barrier()
    t0 = time.perf_counter()
    solver.step(1e-12)
    wall = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    sums = comm.allreduce(np.array([p.mass @ np.sum((p.fields["v"] - v0) ** 2, axis=1),
                                    p.mass @ np.sum(v0 ** 2, axis=1)]))
    return {"error": float(np.sqrt(sums[0] / sums[1])), "time_s": wall}


def run(make_mesh, kinds, sizes, ppcs, comm: MPI.Comm, log=print) -> list[dict]:
    """Every (mesh kind, size, particles per cell, transfer, mass); ``make_mesh(kind, n, comm)``.
    Collective."""
    rows = []
    for kind, n, ppc in itertools.product(kinds, sizes, ppcs):
        mesh = make_mesh(kind, n, comm)
        for transfer, mass in itertools.product(TRANSFERS, MASSES):
            if n == sizes[0]:
                round_trip(mesh, ppc, transfer, mass)  # first call: the kernels load (untimed)
            r = round_trip(mesh, ppc, transfer, mass)
            rows.append({"mesh": kind, "n": n, "h": 1.0 / n, "ppc": ppc, "transfer": transfer, "mass": mass, **r})
            if comm.rank == 0:
                log(f"velocity round trip {kind:17s} n={n:4d} ppc={ppc:2d} {transfer:6s} {mass:10s} "
                    f"error={r['error']:.3e} t={r['time_s']:.4f}s")
    return rows


def rates(rows: list[dict]) -> dict[tuple, float]:
    """The fitted slope of log(error) against log(h) of each (mesh, ppc, transfer, mass) with
    two sizes or more and a nonzero error."""
    out = {}
    for key in dict.fromkeys((r["mesh"], r["ppc"], r["transfer"], r["mass"]) for r in rows):
        rs = [r for r in rows if (r["mesh"], r["ppc"], r["transfer"], r["mass"]) == key and r["error"] > 0]
        if len(rs) >= 2:
            out[key] = float(np.polyfit(np.log([r["h"] for r in rs]), np.log([r["error"] for r in rs]), 1)[0])
    return out


def write(rows: list[dict], out: Path) -> list[str]:
    """``mapping_velocity.csv`` into ``out``; returns the Markdown section of ``mapping.md``."""
    with open(Path(out) / "mapping_velocity.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS)
        w.writeheader()
        w.writerows(rows)
    if not rows:
        return []
    sizes = sorted({r["n"] for r in rows})
    slope = rates(rows)
    lines = ["", "## Velocity round trip of each transfer with each mass", "",
             "One P2G then G2P, no force (fempm.studies.velocity_mapping): the mass-weighted relative change of "
             "a rotation plus a vortex; APIC and TPIC particles carry its gradient. Error at each size (cells per "
             "side), the fitted rate, the time of the finest size's step.", "",
             "| mesh | ppc | transfer | mass | " + " | ".join(f"n={n}" for n in sizes) + " | rate | time s |",
             "|---|---|---|---|" + "---|" * (len(sizes) + 2)]
    for key in dict.fromkeys((r["mesh"], r["ppc"], r["transfer"], r["mass"]) for r in rows):
        rs = {r["n"]: r for r in rows if (r["mesh"], r["ppc"], r["transfer"], r["mass"]) == key}
        rate = f"{slope[key]:.2f}" if key in slope else "-"
        lines.append(f"| {' | '.join(map(str, key))} | " + " | ".join(
            f"{rs[n]['error']:.2e}" if n in rs else "-" for n in sizes) + f" | {rate} | {rs[max(rs)]['time_s']:.4f} |")
    return lines
