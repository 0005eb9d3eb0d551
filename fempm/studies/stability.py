r"""The stability catalogue: ``python -m fempm study stability [--quick] [--out DIR]``.

Each case of :data:`fempm.studies.stability_cases.CASES` (a small scene that stresses one
thing) runs with every option of :func:`options_for` (scheme, mass matrix, particle domain,
mass cut-off, CFL number, velocity transfer APIC, TPIC and XPIC(2) with USL and MUSL; one
factor at a time from USL lumped point FLIP, plus MUSL crossed with consistent mass, FMPM(5)
and CPDI1, F-bar, and Newmark's implicit step), with the default run-health limits (:class:`fempm.stepping.health.Health`:
20 % energy growth beyond the work of the loads, :math:`10^{-2} \le J \le 10^2`, time-step
floor). The outcome of a run is

* ``stable``: it reached its end time;
* ``unstable``: the energy check stopped it (the energy grew beyond the tolerance: the
  discrete scheme amplifies some mode);
* ``aborted``: another check stopped it (J <= 0 or out of bounds, non-finite state, a step
  above the stability limit, a singular mass matrix, a particle leaving the mesh);
* ``refused``: the configuration does not take the option (a ValueError or TypeError before
  the first step: e.g. a law without the implicit step's tangent); not a run that failed.

``reason`` holds the message.

``DIR/stability.csv`` has the columns :data:`COLUMNS`, one row per (case, option), written
after every run; ``DIR/stability.md`` tabulates the outcomes per case and option and
``DIR/stability.png`` shows them as a matrix. A run that blows up is a row, never dropped.
"""

from __future__ import annotations

import csv
import dataclasses
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fempm.io.plot import plot_stability
from fempm.particles.location import OutsideMeshError
from fempm.scene.loop import run
from fempm.stepping.options import SimulationError
from fempm.studies.harness import Provenance, chosen, prepare, sweep
from fempm.studies.stability_cases import CASES
from fempm.transfer.mapping import SingularMassError

__all__ = [
    "BASE", "CFLS", "COLUMNS", "MUSL_VARIATIONS", "TRANSFERS", "VARIATIONS", "label", "options_for", "read_csv", "run_one",
    "run_study", "write_csv", "write_markdown", "write_report",
]

#: a run's outcomes (see the module)
OUTCOMES = ("stable", "unstable", "aborted", "refused")
COLUMNS = ["case", "option", "outcome", "reason", "energy_ratio", "momentum_drift", "j_min", "j_max", "steps", "wall_s"]

#: the transfer options every case runs with: one factor at a time from the default
#: (USL, lumped, point particles, mass cut-off 1e-9, CFL 0.4)
BASE = {"scheme": "USL", "mass": "lumped", "domain": "point", "mass_cutoff": 1e-9, "cfl": 0.4, "transfer": "flip"}
#: the velocity transfers beyond the FLIP blend of the scenes (:mod:`fempm.transfer.transfers`)
TRANSFERS = ({"transfer": "apic"}, {"transfer": "tpic"}, {"transfer": "xpic", "xpic_order": 2})
VARIATIONS = ({}, {"scheme": "MUSL"}, {"scheme": "USF"}, {"mass": "consistent"}, {"mass": "fmpm5"},
              {"domain": "gimp"}, {"domain": "cpdi1"}, {"mass_cutoff": 1e-3}, *TRANSFERS,
              *({"scheme": "MUSL", **t} for t in TRANSFERS))
CFLS = (0.1, 0.25, 0.5, 0.75, 0.9, 1.0)


def label(opts: dict) -> str:
    """An option's name: scheme, mass, domain, cut-off and CFL, e.g. ``USL lumped point cut=1e-09 cfl=0.4``;
    ``fbar`` appended with F-bar, the transfer where it is not the scene's FLIP blend (``apic``,
    ``tpic``, ``xpic2``), and an implicit run named by its dynamics and Courant number
    (``implicit newmark lumped point courant=4``)."""
    o = {**BASE, **opts}
    if o.get("integrator") == "implicit":
        name = f"implicit {o.get('dynamics', 'newmark')} {o['mass']} {o['domain']} courant={o['courant']:g}"
    else:
        name = f"{o['scheme']} {o['mass']} {o['domain']} cut={o['mass_cutoff']:g} cfl={o['cfl']:g}"
    transfer = o["transfer"] + (str(o.get("xpic_order", 2)) if o["transfer"] == "xpic" else "")
    return name + (" fbar" if o.get("volumetric") == "fbar" else "") + ("" if transfer == "flip" else f" {transfer}")


#: the full catalogue also crosses MUSL with the other mass matrices and with CPDI1, and runs
#: F-bar (USL and MUSL) and Newmark's implicit step at a Courant number of 4 (lumped and
#: consistent mass, and lumped with F-bar)
MUSL_VARIATIONS = ({"scheme": "MUSL", "mass": "consistent"}, {"scheme": "MUSL", "mass": "fmpm5"},
                   {"scheme": "MUSL", "domain": "cpdi1"}, {"volumetric": "fbar"},
                   {"scheme": "MUSL", "volumetric": "fbar"}, {"integrator": "implicit", "courant": 4.0},
                   {"integrator": "implicit", "courant": 4.0, "mass": "consistent"},
                   {"integrator": "implicit", "courant": 4.0, "volumetric": "fbar"})


def options_for(case: str, quick: bool = False) -> list[dict]:
    """The options a case runs with: :data:`VARIATIONS` (and, unless ``quick``,
    :data:`MUSL_VARIATIONS`), or for ``cfl`` every CFL number of :data:`CFLS` with USL and MUSL
    lumped and USL (and, unless ``quick``, MUSL) consistent mass, and MUSL lumped with each
    transfer of :data:`TRANSFERS`."""
    if case == "cfl":
        variants = [{}, {"scheme": "MUSL"}, {"mass": "consistent"}] + ([] if quick else [{"scheme": "MUSL", "mass": "consistent"}])
        variants += [{"scheme": "MUSL", **t} for t in TRANSFERS]
        return [{"cfl": c, **v} for v in variants for c in CFLS]
    return [dict(v) for v in VARIATIONS + (() if quick else MUSL_VARIATIONS)]


def run_one(case: str, opts: dict, *, quick: bool, comm: MPI.Comm = MPI.COMM_WORLD) -> dict:
    """One (case, option) run; returns its row (:data:`COLUMNS`)."""

    row = {"case": case, "option": label(opts), "outcome": "stable", "reason": "", "steps": 0,
           "energy_ratio": np.nan, "momentum_drift": np.nan, "j_min": np.nan, "j_max": np.nan}
    t0 = time.perf_counter()
    try:
        scene = CASES[case](quick, comm)
        options = {**BASE, **opts}
        courant = options.pop("courant", None)
        scene.options = dataclasses.replace(scene.options, **options)
        if courant is not None:  # an implicit run: steps of this many explicit (CFL 1) steps of the start
            scene.dt = courant * scene.solver().stable_dt() / scene.options.cfl
        summary = run(scene, None, progress=False)
        _health(row, summary["health"])
        row["steps"] = summary["steps"]
    except (SimulationError, SingularMassError, OutsideMeshError, ValueError, TypeError) as e:  # TypeError: a law
        # without the implicit step's tangent
        msg = " ".join(str(e).split())
        row["outcome"] = "unstable" if "energy growth" in msg else "aborted"
        row["reason"] = f"{type(e).__name__}: {msg}"[:400]
        health = getattr(e, "health", None)
        if health is not None:
            _health(row, health)
            row["steps"] = health["steps"]
        if type(e) in (ValueError, TypeError) and not row["steps"]:  # not a singular mass, a particle outside
            row["outcome"] = "refused"
    row["wall_s"] = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    return row


def _health(row: dict, health: dict) -> None:
    row.update({k: health[k] for k in ("energy_ratio", "momentum_drift", "j_min", "j_max")})


def run_study(out: Path = Path("output/study-stability"), *, quick: bool = False, cases=None,
              comm: MPI.Comm = MPI.COMM_WORLD, log=print, provenance: Provenance | None = None) -> list[dict]:
    """Run the catalogue (``cases``: names of :data:`CASES`, default all) into ``out``.

    Note:
        Collective.
    """
    names = chosen(cases, list(CASES), "case")
    out, provenance = prepare(out, provenance, comm)
    t0 = time.perf_counter()

    def describe(row: dict) -> str:
        return (f"{row['case']:24s} {row['option']:44s} {row['outcome']:9s} E/E0={row['energy_ratio']:.3g} "
                f"J=[{row['j_min']:.3g}, {row['j_max']:.3g}] steps={row['steps']} {row['wall_s']:.1f}s "
                f"{row['reason'][:80]}")

    runs = ((case, opts) for case in names for opts in options_for(case, quick))
    rows = sweep(runs, lambda case, opts: run_one(case, opts, quick=quick, comm=comm), describe, lambda rows: write_csv(rows, out / "stability.csv"), comm, log)
    if comm.rank == 0:
        write_report(rows, out, quick=quick, wall=time.perf_counter() - t0, provenance=provenance)
    return rows


def write_report(rows: list[dict], out: Path, *, quick: bool = False, wall: float | None = None,
                 provenance: Provenance | None = None) -> None:
    """``stability.csv``, ``stability.md``, the outcome matrix ``stability.png`` and
    ``provenance.json`` into ``out`` (``provenance``: what made them, default this process now)."""

    Path(out).mkdir(parents=True, exist_ok=True)
    provenance = provenance or Provenance.now(comm=MPI.COMM_SELF)
    provenance.write(Path(out))
    write_csv(rows, Path(out) / "stability.csv")
    write_markdown(rows, Path(out) / "stability.md", quick=quick, wall=wall, provenance=provenance)
    plot_stability(rows, Path(out) / "stability.png")


def write_csv(rows: list[dict], path: Path) -> None:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)


def read_csv(path: Path) -> list[dict]:
    """Rows of a ``stability.csv`` with their numbers typed."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        r.update({k: float(r[k]) for k in ("energy_ratio", "momentum_drift", "j_min", "j_max", "wall_s")},
                 steps=int(r["steps"]))
    return rows


def write_markdown(rows: list[dict], path: Path, *, quick: bool = False, wall: float | None = None,
                   provenance: Provenance | None = None) -> None:
    """Per case, the outcome of every option (``stable``, ``unstable``, ``aborted`` with the
    cause), the energy ratio and the J range; then a count per option over the cases."""
    lines = [f"# Stability catalogue{' (quick)' if quick else ''}", "",
             (provenance or Provenance.now(comm=MPI.COMM_SELF)).line(), "",
             "Outcome of each case with each transfer option (one factor at a time from USL, lumped, point, "
             "cut-off 1e-9, CFL 0.4; the full catalogue also crosses MUSL with consistent mass, FMPM(5) and CPDI1, and "
             "runs F-bar and Newmark's implicit step at a Courant number of 4), "
             "under the default run-health limits (20 % energy growth beyond the work of the "
             "loads, 1e-2 <= J <= 1e2). E/E0: energy over initial energy plus work at the end (or the stop); "
             "drift: momentum change not explained by the loads, relative to the largest sum of |p|.", ""]
    if wall is not None:
        lines += [f"Run time of the catalogue: {wall:.0f} s ({len(rows)} runs).", ""]
    for case in dict.fromkeys(r["case"] for r in rows):
        lines += [f"## {case}", "", "| option | outcome | E/E0 | drift | J min | J max | steps | wall s | reason |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for r in (r for r in rows if r["case"] == case):
            reason = r["reason"].replace("|", "/")
            lines.append(f"| {r['option']} | {r['outcome']} | {r['energy_ratio']:.4g} | {r['momentum_drift']:.2g} | "
                         f"{r['j_min']:.3g} | {r['j_max']:.3g} | {r['steps']} | {r['wall_s']:.1f} | {reason} |")
        lines.append("")
    lines += ["![outcomes](stability.png)", "", "## Outcomes per option", "",
              "| option | stable | unstable | aborted | refused |", "|---|---|---|---|---|"]
    for opt in dict.fromkeys(r["option"] for r in rows):
        rs = [r for r in rows if r["option"] == opt]
        count = {o: sum(r["outcome"] == o for r in rs) for o in OUTCOMES}
        lines.append(f"| {opt} | {count['stable']} | {count['unstable']} | {count['aborted']} | {count['refused']} |")
    Path(path).write_text("\n".join(lines) + "\n")
