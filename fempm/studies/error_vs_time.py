r"""Error against run time: ``python -m fempm study error-vs-time [--quick] [--out DIR]``.

Which configuration is cheapest for a given error? Every configuration (background mesh,
velocity space, mass matrix: lumped, FMPM(k) or consistent, particle domain, scheme, particles
per cell) of every problem is run at several resolutions; each run records its error and its
wall time (median of ``repeats`` runs; 3 for runs under :data:`REPEAT_BELOW_S` seconds, else 1;
maximum over ranks; each loop configuration run once untimed at its smallest size first, so
that no row times the compilation of its kernels), with the number of ranks times threads it
ran on.

Problems: the loop problems of the convergence study (:data:`fempm.studies.convergence.PROBLEMS`:
the vibrating bar, the 1D and 2D axis-aligned manufactured solutions and the small-amplitude
generalized vortex; error the :math:`V^0`-weighted :math:`L^2` particle displacement error,
maximum over time) and ``mapping``, the particle-to-grid projection alone
(:func:`fempm.studies.mapping.run_case` with the smooth field; error :math:`\|F - f\|_{L^2}`,
time the projection's), and the static problems of :mod:`fempm.studies.scene_problems`
(``cook``: Cook's membrane, its corner's error, explicit damped and quasi-static implicit;
``compaction``: the column's ``stress_error``, quasi-static). The vibrating bar also runs with
Newmark's implicit step (:data:`NEWMARK_BAR`); the column ``integration`` says how a row
integrates in time (``explicit``, ``newmark courant=C``, ``quasi-static N step(s)``).

Outputs: ``DIR/error_vs_time.csv`` with the columns :data:`COLUMNS` (``pareto`` true on the
rows no other row of the problem beats in both error and time), ``DIR/error_vs_time.md`` (the
fronts, and per problem the cheapest run of each mass option below error thresholds) and
``DIR/error_vs_time_<problem>.png`` (log-log error against time, the front drawn).
"""

from __future__ import annotations

import csv
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fempm.io.plot import plot_pareto
from fempm.particles.seeding import create_particles
from fempm.studies import convergence, mapping, scene_problems
from fempm.studies.convergence import Config
from fempm.studies.harness import Provenance, chosen, prepare, read_rows, sweep
from fempm.transfer.domains import half_widths

__all__ = [
    "COLUMNS", "COMPACTION", "COOK", "NEWMARK_BAR", "REPEAT_BELOW_S", "SWEEPS", "Sweep", "pareto", "read_csv", "run_case", "run_study", "threads",
    "write_csv", "write_report",
]

COLUMNS = ["problem", "mesh", "degree", "mass", "domain", "scheme", "cells", "ppc", "error", "wall_s", "repeats",
           "threads", "pareto", "integration", "transfer"]
#: the columns that name a run in the failures' CSV
FAILURE_KEY = [*COLUMNS[:8], "transfer"]
#: runs faster than this are repeated (3 times) and their median time kept
REPEAT_BELOW_S = 2.0


@dataclass(frozen=True)
class Sweep:
    """A problem's sweep: configurations and resolutions (full, quick)."""

    configs: tuple[Config, ...]
    sizes: tuple[int, ...]
    quick_configs: tuple[Config, ...]
    quick_sizes: tuple[int, ...]


def _sweep_1d(scheme: str) -> tuple[Config, ...]:
    out = [Config(mass=m, domain=d, scheme=scheme, ppc=ppc) for m in ("lumped", "fmpm2", "fmpm5", "consistent")
           for d in ("point", "cpdi1") for ppc in (2, 4)]
    out += [Config(degree=2, mass="consistent", scheme=scheme, ppc=3)]
    out += [Config(degree=2, variant="bernstein", mass=m, scheme=scheme, ppc=3) for m in ("lumped", "fmpm5", "consistent")]
    return tuple(out)


def _sweep_2d(scheme: str) -> tuple[Config, ...]:
    out = [Config("structured", mass=m, domain=d, scheme=scheme, ppc=4) for m in ("lumped", "fmpm5", "consistent")
           for d in ("point", "cpdi1")]
    out += [Config("structured", mass="lumped", scheme=scheme, ppc=9)]
    out += [Config("structured", degree=2, mass="consistent", scheme=scheme, ppc=9)]
    out += [Config("unstructured", mass=m, scheme=scheme, ppc=4) for m in ("lumped", "fmpm5", "consistent")]
    out += [Config("unstructured", mass="lumped", domain="cpdi1", scheme=scheme, ppc=4),
            Config("unstructured", degree=2, variant="bernstein", mass="lumped", scheme=scheme, ppc=9)]
    return tuple(out)


def _quick(*masses: str, scheme: str = "USL", ppc: int = 2) -> tuple[Config, ...]:
    return tuple(Config(mass=m, scheme=scheme, ppc=ppc) for m in masses)


#: Newmark's implicit step on the bar at Courant numbers 1 and 4, lumped and consistent mass
NEWMARK_BAR = tuple(Config(mass=m, scheme="MUSL", ppc=2, integrator="newmark", courant=c)
                    for m in ("lumped", "consistent") for c in (1.0, 4.0))
#: Cook's membrane: the scene's explicit damped run, quasi-static implicit in 1 and 10 load steps
COOK = tuple(Config("unstructured", scheme="MUSL", ppc=4, integrator=i, steps=n)
             for i, n in (("explicit", 1), ("quasi-static", 1), ("quasi-static", 10)))
#: the compaction column: point particles, cpGIMP and CPDI1, 5 quasi-static load steps
COMPACTION = tuple(Config(domain=d, ppc=4, integrator="quasi-static", steps=5) for d in ("point", "cpgimp", "cpdi1"))
#: the velocity transfers beside the scenes' FLIP (:mod:`fempm.transfer.transfers`)
TRANSFERS = ("pic", "apic", "tpic", "xpic2")
#: the bar with every transfer, lumped, FMPM(5) and consistent mass (MUSL, 2 particles per cell)
BAR_TRANSFERS = tuple(Config(mass=m, scheme="MUSL", ppc=2, transfer=t) for t in TRANSFERS
                      for m in ("lumped", "fmpm5", "consistent"))
#: the vortex (rotation) with every transfer, lumped, FMPM(5) and consistent mass (MUSL, 4 per cell)
VORTEX_TRANSFERS = tuple(Config("structured", mass=m, scheme="MUSL", ppc=4, transfer=t) for t in TRANSFERS
                         for m in ("lumped", "fmpm5", "consistent"))


SWEEPS: dict[str, Sweep] = {
    "vibrating_bar": Sweep(_sweep_1d("MUSL") + NEWMARK_BAR + BAR_TRANSFERS, (8, 16, 32, 64),
                           _quick("lumped", "fmpm3", "consistent", scheme="MUSL") + NEWMARK_BAR[1:2]
                           + tuple(Config(mass=m, scheme="MUSL", ppc=2, transfer=t) for t in ("pic", "apic", "tpic", "xpic2")
                                   for m in ("lumped", "consistent")), (8, 16)),
    "axis_aligned_1d_G0.05": Sweep(_sweep_1d("USL"), (16, 32, 64, 128), _quick("lumped", "consistent"), (16, 32)),
    "axis_aligned_2d": Sweep(_sweep_2d("USL"), (8, 16, 32), _quick("lumped", "consistent", ppc=4), (8,)),
    "vortex_A0.01": Sweep(_sweep_2d("MUSL") + VORTEX_TRANSFERS, (24, 48),
                          _quick("lumped", scheme="MUSL", ppc=4)
                          + tuple(Config("structured", mass=m, scheme="MUSL", ppc=4, transfer=t)
                                  for t in ("apic", "xpic2") for m in ("lumped", "consistent")), (24,)),
    "mapping": Sweep(
        tuple(Config(mesh, degree=k, mass=m, domain=d, ppc=ppc) for mesh in ("structured", "unstructured")
              for k, masses in ((1, ("lumped", "fmpm2", "fmpm5", "consistent")), (2, ("consistent",)))
              for m in masses for d in ("point", "gimp", "cpdi1") for ppc in (4, 9) if not (k == 2 and ppc == 4)),
        (8, 16, 32, 64),
        tuple(Config("structured", mass=m, ppc=4) for m in ("lumped", "fmpm3", "consistent")), (8, 16)),
    "cook": Sweep(COOK, (6, 12, 24, 48), COOK, (6,)),
    "compaction": Sweep(COMPACTION, (4, 8, 16, 32), COMPACTION[1:2], (4, 8)),
}


def threads() -> int:
    """Ranks times threads per rank (OMP_NUM_THREADS, default 1)."""
    return MPI.COMM_WORLD.size * int(os.environ.get("OMP_NUM_THREADS", "1") or 1)


def _mapping_case(config: Config, cells: int, comm) -> dict:
    mesh = mapping.make_mesh("structured-quad" if config.mesh == "structured" else "unstructured-tri", cells, comm)
    p = create_particles(mesh, config.ppc, jitter=0.5, seed=1)
    ell = half_widths(p)
    p.fields["lp"] = np.minimum(ell, np.minimum(p.x, 1.0 - p.x) * (1 - 1e-9))
    r = mapping.run_case(mesh, p, config.degree, config.mass, "smooth", config.domain)
    return {"error": r["l2_error"], "wall_s": r["time_s"], "status": "ok"}


def _loop_case(problem: str, config: Config, cells: int, comm) -> dict:
    r = convergence.run_case(problem, config, cells, comm)
    return {"error": r["error_l2"] if r["status"] == "ok" else np.nan, "wall_s": r["wall_s"], "status": r["status"],
            "reason": r.get("reason", ""), "mesh": r["mesh"]}


def run_case(problem: str, config: Config, cells: int, comm: MPI.Comm = MPI.COMM_WORLD) -> dict:
    """One (problem, configuration, size), repeated when fast; returns its row."""
    case = (_mapping_case if problem == "mapping" else scene_problems.PROBLEMS.get(problem)
            or (lambda c, n, cm: _loop_case(problem, c, n, cm)))
    row = {"problem": problem, "degree": f"{config.degree}{'B' if config.variant == 'bernstein' else ''}", "mass": config.mass,
           "domain": config.domain, "scheme": "-" if problem == "mapping" else config.scheme, "cells": cells,
           "ppc": config.ppc, "threads": threads(), "integration": config.integration, "transfer": config.transfer}
    try:
        first = case(config, cells, comm)
    except Exception as e:  # noqa: BLE001 - a failed configuration is a row (SingularMassError, unsupported options)
        first = {"error": np.nan, "wall_s": np.nan, "status": type(e).__name__, "reason": " ".join(str(e).split())[:300]}
    walls = [first["wall_s"]]
    if first["status"] == "ok" and first["wall_s"] < REPEAT_BELOW_S:
        walls += [case(config, cells, comm)["wall_s"] for _ in range(2)]
    row.update(error=first["error"], wall_s=float(np.median(walls)), repeats=len(walls), status=first["status"],
               reason=first.get("reason", ""), mesh=first.get("mesh", config.mesh))  # loop rows: "interval" in 1D
    return row


def pareto(rows: list[dict]) -> None:
    """Mark each problem's Pareto-optimal rows: finite error, and no other row with both a
    smaller-or-equal error and time, one of them strictly."""
    for problem in dict.fromkeys(r["problem"] for r in rows):
        rs = sorted((r for r in rows if r["problem"] == problem and np.isfinite(r["error"]) and np.isfinite(r["wall_s"])),
                    key=lambda r: (r["wall_s"], r["error"]))
        best = np.inf
        for r in rows:
            if r["problem"] == problem:
                r["pareto"] = False
        for r in rs:
            if r["error"] < best:
                r["pareto"] = True
                best = r["error"]


def _warm_up(name: str, config: Config, sweep: Sweep, quick: bool, comm: MPI.Comm) -> None:
    """Run a loop problem's configuration once at its sweep's smallest size, untimed: its
    compiled kernels (numba, one set per cell type, space, domain, mass and pass) load or
    compile on first use, which would otherwise be timed in its first row (a compilation of
    several seconds is a run above :data:`REPEAT_BELOW_S`, timed once)."""
    if name == "mapping":
        return
    run_case(name, config, (sweep.quick_sizes if quick else sweep.sizes)[0], comm)


def run_study(out: Path = Path("output/study-error-vs-time"), *, quick: bool = False, problems=None,
              comm: MPI.Comm = MPI.COMM_WORLD, log=print, provenance: Provenance | None = None) -> list[dict]:
    """Run the sweeps (``problems``: names of :data:`SWEEPS`, default all) into ``out``; the CSV
    is rewritten after every run.

    Note:
        Collective.
    """
    names = chosen(problems, list(SWEEPS), "problem")
    out, provenance = prepare(out, provenance, comm)
    t0 = time.perf_counter()
    run_case("mapping", Config(ppc=4), 4, comm)  # first-call costs (imports, PETSc set-up) untimed

    def cases():
        for name in names:
            sw = SWEEPS[name]
            for config in (sw.quick_configs if quick else sw.configs):
                _warm_up(name, config, sw, quick, comm)
                for cells in (sw.quick_sizes if quick else sw.sizes):
                    if config.degree == 1 or name == "mapping" or cells <= max(sw.sizes[:-1], default=cells):
                        yield name, config, cells, comm  # the P2 spaces stop one size earlier

    def describe(row: dict) -> str:
        return (f"{row['problem']:22s} {row['mesh']:12s} P{row['degree']:2s} {row['mass']:10s} {row['domain']:6s} "
                f"{row['scheme']:4s} {row['transfer']:5s} cells={row['cells']:4d} ppc={row['ppc']} "
                f"error={row['error']:.3e} t={row['wall_s']:.3f}s x{row['repeats']} {row['status']}")

    def save(rows: list[dict]) -> None:
        pareto(rows)
        write_csv(rows, out / "error_vs_time.csv")

    rows = sweep(cases(), run_case, describe, save, comm, log)
    pareto(rows)
    if comm.rank == 0:
        write_report(rows, out, quick=quick, wall=time.perf_counter() - t0, provenance=provenance)
    return rows


def write_csv(rows: list[dict], path: Path) -> None:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    failed = [r for r in rows if r.get("status", "ok") != "ok"]
    with open(Path(path).with_name("error_vs_time_failures.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FAILURE_KEY + ["status", "reason"], extrasaction="ignore")
        w.writeheader()
        w.writerows(failed)


def read_csv(path: Path) -> list[dict]:
    """Rows of an ``error_vs_time.csv`` with their numbers typed, and the status and reason of
    failed runs from ``error_vs_time_failures.csv`` beside it (to write the report again)."""
    rows = []
    for r, f in read_rows(path, "error_vs_time_failures.csv", FAILURE_KEY):
        r.update(status=f.get("status", "ok"), reason=f.get("reason", ""))
        r.update(error=float(r["error"]), wall_s=float(r["wall_s"]), cells=int(r["cells"]), ppc=int(r["ppc"]),
                 repeats=int(r["repeats"]), threads=int(r["threads"]), pareto=r["pareto"] == "True",
                 transfer=r.get("transfer") or "flip")
        rows.append(r)
    return rows


def _name(r: dict) -> str:
    integration = r.get("integration", "explicit") or "explicit"
    transfer = r.get("transfer", "flip") or "flip"
    return (f"{r['mesh']} P{r['degree']} {r['mass']} {r['domain']} {r['scheme']} ppc={r['ppc']} n={r['cells']}"
            + ("" if integration == "explicit" else f" {integration}") + ("" if transfer == "flip" else f" {transfer}"))


def _transfer_table(rs: list[dict]) -> list[str]:
    """Where a problem ran several transfers: per transfer and mass (the explicit runs of the
    transfer sweeps' scheme and particles per cell), the error at each size, the wall time, and
    the error times the time (the lower, the cheaper a given error)."""
    transfers = list(dict.fromkeys(r.get("transfer", "flip") or "flip" for r in rs))
    if len(transfers) < 2:
        return []
    swept = [r for r in rs if (r.get("transfer") or "flip") != "flip"]
    keys = {(r["scheme"], r["ppc"], r["mesh"], r["domain"], r["degree"]) for r in swept}
    sizes = sorted({r["cells"] for r in swept})
    lines = ["", "Per transfer and mass (the transfer sweep's " + ", ".join(
        f"{m} {s} ppc={p}" for s, p, m, _, _ in sorted(keys)) + "; error (wall s) at each size; "
             "the last column the error times the time of the finest run):", "",
             "| transfer | mass | " + " | ".join(f"n={n}" for n in sizes) + " | error x s |",
             "|---|---|" + "---|" * (len(sizes) + 1)]
    for t in transfers:
        for m in dict.fromkeys(r["mass"] for r in swept):
            hit = {r["cells"]: r for r in rs if (r.get("transfer") or "flip") == t and r["mass"] == m
                   and (r["scheme"], r["ppc"], r["mesh"], r["domain"], r["degree"]) in keys
                   and (r.get("integration") or "explicit") == "explicit"}
            if not hit:
                continue
            cells = [f"{hit[n]['error']:.3e} ({hit[n]['wall_s']:.3g})" if n in hit else "-" for n in sizes]
            last = hit[max(hit)]
            lines.append(f"| {t} | {m} | " + " | ".join(cells) + f" | {last['error'] * last['wall_s']:.3e} |")
    return lines


def write_report(rows: list[dict], out: Path, *, quick: bool = False, wall: float | None = None,
                 provenance: Provenance | None = None) -> None:
    """CSV, Markdown summary, one figure per problem and ``provenance.json`` (``provenance``: what
    made them, default this process now)."""

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    provenance = provenance or Provenance.now(comm=MPI.COMM_SELF)
    provenance.write(out)
    pareto(rows)
    write_csv(rows, out / "error_vs_time.csv")
    lines = [f"# Error against run time{' (quick)' if quick else ''}", "", provenance.line(), "",
             "Error: V0-weighted L2 particle displacement error, maximum over time (loop problems), or the L2 error "
             "of the projected smooth field (mapping). Time: median wall time of the run (projection alone for "
             f"mapping), on {rows[0]['threads'] if rows else 1} rank(s) x thread(s) of a machine with "
             f"{os.cpu_count()} cores.", ""]
    if wall is not None:
        lines += [f"Run time of the study: {wall:.0f} s ({len(rows)} configurations x sizes).", ""]
    for problem in dict.fromkeys(r["problem"] for r in rows):
        rs = [r for r in rows if r["problem"] == problem]
        front = sorted((r for r in rs if r["pareto"]), key=lambda r: r["wall_s"])
        lines += [f"## {problem}", "", "Pareto front (cheapest first):", "", "| configuration | error | wall s |", "|---|---|---|"]
        lines += [f"| {_name(r)} | {r['error']:.3e} | {r['wall_s']:.4g} |" for r in front]
        ok = [r for r in rs if np.isfinite(r["error"])]
        if ok:
            errs = sorted(r["error"] for r in ok)
            targets = sorted({float(f"{errs[int(q * (len(errs) - 1))]:.1e}") for q in (0.1, 0.3, 0.6)})
            masses = list(dict.fromkeys(r["mass"] for r in ok))
            lines += ["", "Cheapest run reaching each error, per mass option (time in s; - none reaches it):", "",
                      "| error <= | " + " | ".join(masses) + " |", "|---|" + "---|" * len(masses)]
            for e in targets:
                cells = []
                for m in masses:
                    hit = [r for r in ok if r["mass"] == m and r["error"] <= e]
                    cells.append(f"{min(r['wall_s'] for r in hit):.3g}" if hit else "-")
                lines.append(f"| {e:.1e} | " + " | ".join(cells) + " |")
        lines += _transfer_table(rs)
        failed = [r for r in rs if r.get("status", "ok") != "ok"]
        if failed:
            lines += ["", f"{len(failed)} run(s) failed (reasons in error_vs_time_failures.csv)."]
        lines.append("")
        plot_pareto(rs, out / f"error_vs_time_{problem}.png", title=f"{problem}: error against wall time")
    (out / "error_vs_time.md").write_text("\n".join(lines) + "\n")
