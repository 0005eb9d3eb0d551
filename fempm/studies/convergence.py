r"""Convergence study of the explicit MPM loop on exact and manufactured solutions.

``python -m fempm study convergence [--quick] [--out DIR]`` runs every configuration of every
problem (:data:`PROBLEMS`, :func:`configurations`) at a sequence of resolutions, each with a
fixed time step proportional to the cell size,
:math:`\Delta t = \mathrm{cfl}\, h / (k\, (c + v_{max}))` (cfl per problem, smaller for
consistent mass on the vortex) (:math:`c` the dilatational wave
speed, :math:`v_{max}` the largest exact speed, :math:`k` the space's degree), and records the
particle displacement errors against the exact motion (:func:`fempm.verification.errors.particle_errors`,
each the maximum over time):

* ``DIR/convergence.csv``, one row per run with the columns :data:`COLUMNS`; ``status`` is
  ``ok`` or the class of the error that ended the run (the errors are then those measured
  until it stopped);
* ``DIR/convergence.md``, the fitted rate of each configuration
  (``numpy.polyfit`` of :math:`\log e` against :math:`\log h` over its finest ``ok`` sizes,
  at most :data:`FIT_SIZES`), with a verdict, and the reasons of the failed runs;
* ``DIR/convergence_<problem>.png``, the :math:`L^2` error against :math:`h` per problem.

The problems are the smooth exact and manufactured motions of :mod:`fempm.verification.manufactured` and,
with plasticity, the elastic-plastic impact of :mod:`fempm.verification.plastic_impact` (two waves, a jump
in velocity at each: the displacement error converges at most like :math:`h`).

A run that fails or stops converging stays a row of the table.
"""

from __future__ import annotations

import csv
import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fempm.io.plot import plot_convergence
from fempm.scene.loop import run as run_scene
from fempm.scenes.manufactured import manufactured_scene
from fempm.studies.harness import Provenance, chosen, prepare, read_rows, sweep
from fempm.transfer.mass_models import mass_model
from fempm.verification import manufactured as mf
from fempm.verification.errors import ErrorHistory
from fempm.verification.plastic_impact import plastic_impact

__all__ = [
    "COLUMNS", "DOMAINS", "FAILURE_COLUMNS", "FIT_SIZES", "PROBLEMS", "SERIES", "Config", "ProblemSpec",
    "fitted_rates", "max_speed", "read_csv", "run", "run_case", "write_csv", "write_markdown", "write_report",
]

COLUMNS = ["problem", "mesh", "degree", "variant", "mass", "domain", "scheme", "cells", "h", "dt", "steps",
           "error_max", "error_rms", "error_l2", "wall_s", "status"]
#: the number of finest ok sizes a rate is fitted over
FIT_SIZES = 3
DOMAINS = ("point", "ugimp", "cpgimp", "cpdi1", "cpdi2")


@dataclass(frozen=True)
class Config:
    """One configuration of a problem: background mesh kind, velocity space (degree and
    Lagrange variant), mass matrix, particle domain, scheme and particles per cell."""

    mesh: str = "structured"
    degree: int = 1
    variant: str = "default"
    mass: str = "lumped"
    domain: str = "point"
    scheme: str = "USL"
    ppc: int | None = None
    max_cells: int | None = None  # the finest size run (the costly P2 spaces in 2D stop earlier)
    #: "explicit", or the implicit step's dynamics: "newmark" (time steps of ``courant`` times the
    #: cell's crossing time by the wave) or "quasi-static" (``steps`` load steps)
    integrator: str = "explicit"
    courant: float = 4.0
    steps: int = 1
    #: the velocity transfer: flip (the scene's blend), pic, apic, tpic or xpicM (XPIC of order M)
    transfer: str = "flip"

    @property
    def transfer_options(self) -> dict:
        """The :class:`~fempm.stepping.StepOptions` of :attr:`transfer` (none for the scene's own)."""
        if self.transfer == "flip":
            return {}
        if self.transfer.startswith("xpic"):
            return {"transfer": "xpic", "xpic_order": int(self.transfer[4:] or 2)}
        return {"transfer": self.transfer}

    @property
    def label(self) -> str:
        space = f"P{self.degree}" + ("B" if self.variant == "bernstein" else "")
        return f"{self.mesh} {space} {self.mass} {self.domain} {self.scheme}" + (
            "" if self.integrator == "explicit" else f" {self.integration}") + (
            "" if self.transfer == "flip" else f" {self.transfer}")

    @property
    def integration(self) -> str:
        """How the run integrates in time: ``explicit``, ``newmark courant=C``, ``quasi-static N steps``."""
        if self.integrator == "newmark":
            return f"newmark courant={self.courant:g}"
        if self.integrator == "quasi-static":
            return f"quasi-static {self.steps} step(s)"
        return "explicit"


@dataclass(frozen=True)
class ProblemSpec:
    """A problem of the study: the exact solution, its sizes (full, quick), the CFL number of
    the fixed time step (``consistent_cfl`` for consistent mass, whose stable step is smaller,
    default the same) and its configurations (full, quick)."""

    make: object
    sizes: tuple[int, ...]
    quick_sizes: tuple[int, ...]
    cfl: float
    configs: tuple[Config, ...]
    quick_configs: tuple[Config, ...]
    consistent_cfl: float | None = None


def _c1d(**kw) -> list[Config]:
    """1D configurations: P1 lumped and consistent with every domain, P2 consistent and
    Bernstein P2 (lumped and consistent) with point, cpGIMP and CPDI1 particles (3 per cell)."""
    out = [Config(mass=m, domain=d, **kw) for m in ("lumped", "consistent") for d in DOMAINS]
    out += [Config(degree=2, mass="consistent", domain=d, ppc=3, **kw) for d in ("point", "cpgimp", "cpdi1")]
    out += [Config(degree=2, variant="bernstein", mass=m, domain=d, ppc=3, **kw)
            for m in ("lumped", "consistent") for d in ("point", "cpgimp")]
    return out


def _c2d(scheme: str, unstructured: tuple[str, ...], p2_max: int) -> list[Config]:
    """2D configurations: structured quadrilaterals with P1 lumped (every domain) and consistent
    (point, cpGIMP, CPDI1), Q2 consistent (3x3 particles); unstructured triangles with P1
    lumped (``unstructured`` domains) and consistent, P2 consistent and Bernstein P2 lumped
    (3x3 particles). The P2 spaces run up to ``p2_max`` cells."""
    out = [Config("structured", mass="lumped", domain=d, scheme=scheme) for d in DOMAINS]
    out += [Config("structured", mass="consistent", domain=d, scheme=scheme) for d in ("point", "cpgimp", "cpdi1")]
    out += [Config("structured", degree=2, mass="consistent", scheme=scheme, ppc=9, max_cells=p2_max)]
    out += [Config("unstructured", mass="lumped", domain=d, scheme=scheme) for d in unstructured]
    out += [Config("unstructured", mass="consistent", scheme=scheme),
            Config("unstructured", degree=2, mass="consistent", scheme=scheme, ppc=9, max_cells=p2_max),
            Config("unstructured", degree=2, variant="bernstein", mass="lumped", scheme=scheme, ppc=9, max_cells=p2_max)]
    return out


def _quick1d(*domains: str) -> tuple[Config, ...]:
    return tuple(Config(mass=m, domain=d) for d in domains for m in ("lumped", "consistent"))


PROBLEMS: dict[str, ProblemSpec] = {
    "vibrating_bar": ProblemSpec(lambda: mf.vibrating_bar(t_end=10.0), (8, 16, 32, 64, 128, 256), (8, 16, 32),
                                 0.2, tuple([Config(domain="point")] + _c1d(scheme="MUSL")), _quick1d("point")),
    "axis_aligned_1d_G1e-4": ProblemSpec(lambda: mf.axis_aligned_1d(1e-4), (8, 16, 32, 64, 128, 256),
                                         (8, 16, 32, 64), 0.2, tuple(_c1d()), _quick1d("point", "cpgimp")),
    "axis_aligned_1d_G0.05": ProblemSpec(lambda: mf.axis_aligned_1d(0.05), (8, 16, 32, 64, 128, 256),
                                         (16, 32, 64, 128), 0.2, tuple(_c1d()),
                                         tuple(Config(domain=d) for d in ("point", "ugimp", "cpgimp", "cpdi1", "cpdi2"))),
    "axis_aligned_2d": ProblemSpec(lambda: mf.axis_aligned(0.05, 2), (8, 16, 32, 64), (8, 16), 0.1,
                                   tuple(_c2d("USL", ("point", "cpgimp", "cpdi2"), 32)),
                                   (Config(domain="point"), Config(domain="cpdi1"))),
    "vortex_A0.01": ProblemSpec(lambda: mf.generalized_vortex(0.01), (24, 48, 96, 192), (24, 48), 0.2,
                                tuple(_c2d("MUSL", ("point", "cpgimp", "cpdi1", "cpdi2"), 96)),
                                (Config(domain="point", scheme="MUSL"), Config(domain="cpdi2", scheme="MUSL")), 0.1),
    "vortex_A1": ProblemSpec(lambda: mf.generalized_vortex(1.0), (24, 48, 96), (24, 48), 0.2,
                             tuple([Config(domain=d, scheme="MUSL") for d in DOMAINS]
                                   + [Config(mass="consistent", domain=d, scheme="MUSL") for d in ("point", "cpdi2")]
                                   + [Config("unstructured", domain=d, scheme="MUSL") for d in ("point", "cpdi1", "cpdi2")]),
                             (Config(domain="cpdi1", scheme="MUSL"), Config(domain="cpdi2", scheme="MUSL")), 0.1),
    "plastic_impact": ProblemSpec(plastic_impact, (16, 32, 64, 128), (16, 32, 64), 0.2,
                                  tuple(Config(mass=m, domain=d) for m in ("lumped", "consistent") for d in ("point", "cpdi1"))
                                  + (Config(scheme="MUSL"), Config("triangles")),
                                  (Config(), Config(mass="consistent")), 0.1),
}


def max_speed(problem) -> float:
    """Dilatational wave speed plus the largest exact particle speed (sampled over the body
    and the run)."""
    rng = np.random.default_rng(0)
    lo, hi = np.array(problem.lower), np.array(problem.upper)
    X = lo + (hi - lo) * rng.uniform(size=(4000, problem.dim))
    X = X[problem.contains(X)]
    v = max(np.linalg.norm(problem.velocity(X, t), axis=1).max() for t in np.linspace(0, problem.t_end, 21))
    F = np.broadcast_to(np.eye(problem.dim), (1, problem.dim, problem.dim))
    c = float(problem.material.wave_speed(F, np.array([problem.rho0]))[0])
    return c + float(v)


def run_case(name: str, config: Config, cells: int, comm: MPI.Comm = MPI.COMM_WORLD) -> dict:
    """One run: returns its row (:data:`COLUMNS`) and the failure message (``reason``)."""

    spec = PROBLEMS[name]
    problem = spec.make()
    row = {"problem": name, "mesh": config.mesh if problem.dim > 1 else "interval", "degree": config.degree,
           "variant": config.variant, "mass": config.mass, "domain": config.domain, "scheme": config.scheme,
           "cells": cells, "steps": 0, "status": "ok", "reason": "", "transfer": config.transfer}
    t0 = time.perf_counter()
    history = None
    try:
        scene = manufactured_scene(problem, cells, mesh=config.mesh, ppc=config.ppc, degree=config.degree,
                                   variant=None if config.variant == "default" else config.variant, mass=config.mass,
                                   domain=config.domain, scheme=config.scheme, comm=comm)
        h = scene.params["h"]
        if config.transfer_options:
            scene.options = dataclasses.replace(scene.options, **config.transfer_options)
        cfl = spec.consistent_cfl if mass_model(config.mass).matrix and spec.consistent_cfl else spec.cfl
        if config.integrator == "newmark":  # Newmark's implicit step at a Courant number
            scene.options = dataclasses.replace(scene.options, integrator="implicit", dynamics="newmark")
            cfl = config.courant
        dt = cfl * h / (config.degree * max_speed(problem))
        scene.dt = dt
        row.update(h=h, dt=dt)
        history = ErrorHistory(problem, scene.particles)
        summary = run_scene(scene, None, progress=False, callback=history)
        row["steps"] = summary["steps"]
    except Exception as e:  # noqa: BLE001 - every failure is a row of the table, with its class and message
        row["status"] = type(e).__name__
        row["reason"] = " ".join(str(e).split())[:300]
        row.setdefault("h", np.nan)
        row.setdefault("dt", np.nan)
        if history is not None:
            row["steps"] = len(history.rows) - 1
    row["wall_s"] = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    worst = history.worst if history is not None else {"max": np.nan, "rms": np.nan, "l2": np.nan}
    row.update(error_max=worst["max"], error_rms=worst["rms"], error_l2=worst["l2"])
    return row


def run(out: Path = Path("output/study-convergence"), *, quick: bool = False, problems=None,
        comm: MPI.Comm = MPI.COMM_WORLD, log=print, provenance: Provenance | None = None) -> list[dict]:
    """Run the study (``problems``: names of :data:`PROBLEMS`, default all), write its outputs
    into ``out`` (CSV after every run, so that nothing measured is lost) and return the rows.

    Note:
        Collective.
    """
    names = chosen(problems, list(PROBLEMS), "problem")
    out, provenance = prepare(out, provenance, comm)

    def cases():
        for name in names:
            spec = PROBLEMS[name]
            for config in (spec.quick_configs if quick else spec.configs):
                for cells in (spec.quick_sizes if quick else spec.sizes):
                    if config.max_cells is None or cells <= config.max_cells:
                        yield name, config, cells, comm

    def describe(row: dict) -> str:
        label = (f"{row['mesh']} P{row['degree']}{'B' if row['variant'] == 'bernstein' else ''} {row['mass']} "
                 f"{row['domain']} {row['scheme']}")
        return (f"{row['problem']:22s} {label:40s} cells={row['cells']:4d} L2={row['error_l2']:.3e} "
                f"max={row['error_max']:.3e} steps={row['steps']:5d} {row['wall_s']:7.1f}s {row['status']}")

    rows = sweep(cases(), run_case, describe, lambda rows: write_csv(rows, out / "convergence.csv"), comm, log)
    if comm.rank == 0:
        write_report(rows, out, quick=quick, provenance=provenance)
    return rows


FAILURE_COLUMNS = ["problem", "mesh", "degree", "variant", "mass", "domain", "scheme", "cells", "status", "reason"]


def read_csv(path: Path) -> list[dict]:
    """Rows of a ``convergence.csv`` with their numbers typed, and the reasons of failed runs
    from ``convergence_failures.csv`` beside it when there is one (e.g. to merge studies run
    in parts and write their report again with :func:`write_report`)."""
    ints, floats = ("degree", "cells", "steps"), ("h", "dt", "error_max", "error_rms", "error_l2", "wall_s")
    rows = []
    for r, failed in read_rows(path, "convergence_failures.csv", FAILURE_COLUMNS[:8]):
        r.update({k: int(r[k]) for k in ints}, **{k: float(r[k]) for k in floats}, reason=failed.get("reason", ""))
        rows.append(r)
    return rows


def write_report(rows: list[dict], out: Path, *, quick: bool = False, provenance: Provenance | None = None) -> None:
    """``convergence.csv``, ``convergence.md``, the figures of ``rows`` and ``provenance.json``
    into ``out`` (``provenance``: what made them, default this process now)."""

    out = Path(out)
    provenance = provenance or Provenance.now(comm=MPI.COMM_SELF)
    provenance.write(out)
    write_csv(rows, out / "convergence.csv")
    write_markdown(rows, out / "convergence.md", quick=quick, provenance=provenance)
    for name in dict.fromkeys(r["problem"] for r in rows):
        plot_convergence([r for r in rows if r["problem"] == name], out / f"convergence_{name}.png", title=name)


def write_csv(rows: list[dict], path: Path) -> None:
    """``convergence.csv`` (:data:`COLUMNS`) and, beside it, ``convergence_failures.csv`` with the
    message that stopped each failed run."""
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    with open(Path(path).with_name("convergence_failures.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FAILURE_COLUMNS, extrasaction="ignore")
        w.writeheader()
        w.writerows(r for r in rows if r["status"] != "ok")


SERIES = ("problem", "mesh", "degree", "variant", "mass", "domain", "scheme")


def fitted_rates(rows: list[dict]) -> list[dict]:
    """Per configuration: the slopes of log(error) against log(h) (L2 and max norms) over its
    finest ok sizes (at most :data:`FIT_SIZES`), the sizes used, the L2 error at the finest ok
    size, and a verdict: ``converging`` (L2 rate >= 1), ``slow`` (0.3 <= rate < 1), ``not
    converging`` (rate < 0.3, or fewer than two ok sizes), with ``, stops when refined`` where
    a run on a finer mesh than the finest ok one failed."""
    out = []
    keys = []
    for r in rows:
        k = tuple(r[c] for c in SERIES)
        if k not in keys:
            keys.append(k)
    for key in keys:
        rs = [r for r in rows if tuple(r[c] for c in SERIES) == key]
        ok = sorted((r for r in rs if r["status"] == "ok"), key=lambda r: r["h"])[:FIT_SIZES]
        rate = {"l2": np.nan, "max": np.nan}
        if len(ok) >= 2:
            for norm in rate:
                rate[norm] = float(np.polyfit(np.log([r["h"] for r in ok]), np.log([r[f"error_{norm}"] for r in ok]), 1)[0])
        failed = [r for r in rs if r["status"] != "ok"]
        if len(ok) < 2 or rate["l2"] < 0.3:
            verdict = "not converging"
        else:
            verdict = "converging" if rate["l2"] >= 1.0 else "slow"
        if ok and any(r["h"] < ok[0]["h"] for r in failed if np.isfinite(r["h"])):
            verdict += ", stops when refined"
        out.append({**dict(zip(SERIES, key)), "rate_l2": rate["l2"], "rate_max": rate["max"],
                    "sizes": ",".join(str(r["cells"]) for r in sorted(ok, key=lambda r: r["cells"])),
                    "finest_l2": ok[0]["error_l2"] if ok else np.nan, "failed": len(failed),
                    "verdict": verdict})
    return out


def write_markdown(rows: list[dict], path: Path, *, quick: bool = False, provenance: Provenance | None = None) -> None:
    """The fitted rates of every configuration and the runs that stopped, as Markdown."""
    rates = fitted_rates(rows)
    lines = [f"# Convergence of the MPM loop{' (quick)' if quick else ''}", "",
             (provenance or Provenance.now(comm=MPI.COMM_SELF)).line(), "",
             "Displacement error of the particles against the exact motion, maximum over time; "
             f"rates fitted (numpy.polyfit) over the finest {FIT_SIZES} ok sizes of each configuration.", "",
             "| problem | mesh | space | mass | domain | scheme | sizes fitted | finest L2 error | rate L2 | rate max | failed runs | verdict |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rates:
        space = f"P{r['degree']}" + (" Bernstein" if r["variant"] == "bernstein" else "")
        lines.append(f"| {r['problem']} | {r['mesh']} | {space} | {r['mass']} | {r['domain']} | {r['scheme']} | "
                     f"{r['sizes']} | {r['finest_l2']:.3e} | {r['rate_l2']:.2f} | {r['rate_max']:.2f} | {r['failed']} | "
                     f"{r['verdict']} |")
    failed = [r for r in rows if r["status"] != "ok"]
    if failed:
        lines += ["", "## Runs that stopped", "", "| problem | configuration | cells | steps | status | reason |",
                  "|---|---|---|---|---|---|"]
        for r in failed:
            cfg = f"{r['mesh']} P{r['degree']}{'B' if r['variant'] == 'bernstein' else ''} {r['mass']} {r['domain']} {r['scheme']}"
            reason = r["reason"].replace("|", "/")
            lines.append(f"| {r['problem']} | {cfg} | {r['cells']} | {r['steps']} | {r['status']} | {reason} |")
    Path(path).write_text("\n".join(lines) + "\n")
