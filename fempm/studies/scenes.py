r"""Convergence of the scenes' headline numbers under refinement.

``python -m fempm study scenes [--quick] [--problems NAME ...] [--out DIR]`` runs each series
(:data:`SERIES`: a scene, the summary value it reports, a variant of its options, and the sizes
it is refined over) at every size and writes

* ``DIR/scenes_convergence.csv``, one row per run with the columns :data:`COLUMNS`: the
  ``value``, its ``reference`` (a closed form or an independent solution; empty where there is
  none), the relative ``error`` (against the reference, else against the extrapolated value),
  and the series' fitted ``order`` and ``extrapolated`` value on each of its rows;
* ``DIR/scenes_convergence.md``, the table with the provenance line, and the runs that failed
  with their reasons (also in ``DIR/scenes_failures.csv``: scene, variant, size, reason);
* ``DIR/scenes_<scene>.png``, the error of each of the scene's series against the cell size.

The order: with a reference, the slope of :math:`\log |e|` against :math:`\log h` fitted by
``numpy.polyfit`` over the sizes that ran (the errors' sign may change: the fit is then
meaningless and the table says so through a low or negative order); without one, from the last
three values of a series refined by a constant ratio :math:`r`,
:math:`p = \log(|v_2 - v_1| / |v_3 - v_2|) / \log r`. The extrapolated value is Richardson's,
:math:`v_3 + (v_3 - v_2) / (r^p - 1)`, where that order is steady (the same within 0.5 from
the three sizes before, and between 0.3 and 6), else empty. Where a scene has no reference
the extrapolated value and its spread are the record, not a verified value.

The cell size :math:`h` of a size is its value for the scenes refined by a length (Cook's ``h``)
and its inverse for those refined by a count of cells.
"""

from __future__ import annotations

import csv
import dataclasses
import inspect
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fempm.io.plot import plot_errors
from fempm.scene.loop import run as run_scene
from fempm.scenes import SCENES
from fempm.scenes.cook import FE_REFERENCE
from fempm.studies.harness import Provenance, chosen, prepare, sweep

__all__ = ["COLUMNS", "COOK_FE", "SERIES", "Series", "fit", "run_series", "run_study", "write_report"]

COLUMNS = ["scene", "quantity", "variant", "size", "value", "reference", "error", "order", "extrapolated", "wall_s"]

#: Cook's membrane, the vertical displacement of C per unit load (:data:`fempm.scenes.cook.FE_REFERENCE`)
COOK_FE = FE_REFERENCE


@dataclass(frozen=True)
class Series:
    """A scene's headline value refined over sizes.

    Attributes:
        scene: the scene's name (:data:`fempm.scenes.SCENES`).
        quantity: the summary key of the value (``key[i]``: an entry of a list).
        variant: the series' label.
        size: the scene option refined (``h``: a length, else a count of cells).
        sizes: the sizes of the full study, coarse to fine.
        quick: the sizes of ``--quick`` (none: not in the quick study).
        options: the scene's other options.
        reference: the exact or independent value, a summary key holding it (``"=key"``), or None.
        scale: the value is the summary's times this.
        steps: implicit runs: the number of fixed steps to ``t_end`` (0: the scene's own step).
    """

    scene: str
    quantity: str
    variant: str
    size: str
    sizes: tuple
    quick: tuple
    options: dict = field(default_factory=dict)
    reference: float | str | None = None
    scale: float = 1.0
    steps: int = 0

    @property
    def name(self) -> str:
        return f"{self.scene}/{self.variant}"


def _cook(nu: float, volumetric: str, integrator: str) -> Series:
    implicit = integrator == "implicit"
    options = {"nu": nu, "volumetric": volumetric}
    if implicit:
        options |= {"integrator": "implicit", "dynamics": "quasi-static"}
    label = f"nu={nu:.4g} {volumetric} {'quasi-static' if implicit else 'explicit'}"
    # --quick: the implicit runs only (the explicit ones damp to rest over thousands of steps,
    # 33 times more at nu = 0.4999)
    return Series("cook", "corner_displacement[1]", label, "h", (4.0, 2.0, 1.0, 0.5), (4.0, 2.0) if implicit else (),
                  options, COOK_FE[nu], 1e3, 10 if implicit else 0)


#: every series of the study, by name (``scene/variant``)
SERIES = {s.name: s for s in [
    *[_cook(nu, vol, integ) for nu in (1 / 3, 0.4999) for vol in ("standard", "fbar") for integ in ("implicit", "explicit")],
    Series("bar", "period", "explicit MUSL", "cells", (8, 16, 32, 64), (8, 16), {"t_end": 25.0}, "=period_reference"),
    Series("bar", "period", "Newmark", "cells", (8, 16, 32, 64), (8, 16),
           {"t_end": 25.0, "integrator": "implicit", "dynamics": "newmark"}, "=period_reference", steps=250),
    Series("compaction", "stress_error", "point", "cells", (4, 8, 16, 32), (4, 8), {}, 0.0),
    Series("wave", "reflected_energy_ratio", "absorbing", "cells", (32, 64, 128, 256), (32, 64), {}, 0.0),
    Series("wave", "reflected_energy_ratio", "fixed", "cells", (32, 64, 128, 256), (32, 64), {"boundary": "fixed"}, 1.0),
    *[Series("incline", "acceleration", f"{body} mu={mu:g} {plane}{'' if turned else ' axis-aligned'}", "cells",
             (4, 8, 16, 32), (4, 8), {"body": body, "friction": mu, "plane": plane, "turned": turned}, "=analytic")
      for body, mu, plane, turned in (("block", 0.2, "grid", True), ("block", 0.2, "tagged", True),
                                      ("disk", 0.3, "collider", True), ("disk", 0.3, "collider", False),
                                      ("disk", 1.0, "collider", False))],
    Series("footing", "bearing_ratio", "standard", "cells", (8, 16, 32, 64), (4, 8), {}, 1.0),
    Series("footing", "bearing_ratio", "fbar", "cells", (8, 16, 32, 64), (4, 8), {"volumetric": "fbar"}, 1.0),
    # F-bar's patch average integrated by 16 particles a cell (4 leave it 7.6 % soft: docs/colliders.md)
    Series("footing", "bearing_ratio", "fbar ppc=16", "cells", (4, 8, 16, 32), (), {"volumetric": "fbar", "ppc": 16}, 1.0),
    Series("silo", "discharge_rate", "mu(I)", "cells", (5, 7, 10, 15), (3, 4), {}, None),
    Series("silo", "discharge_rate", "Drucker-Prager", "cells", (5, 7, 10, 15), (3, 4), {"law": "dp"}, None),
    Series("column", "runout", "Drucker-Prager", "cells", (8, 16, 32, 64), (8, 16), {}, None),
    Series("bowl", "period", "slip", "cells", (4, 8, 16, 32), (4, 8), {}, "=period_reference"),
    Series("bowl", "period", "friction 0.3 flip 0.95", "cells", (4, 8, 16, 32), (4, 8),
           {"wall": "friction", "flip": 0.95}, "=period_reference"),
]}

#: the stepping options a scene takes through the study rather than its builder
_STEPPING = ("integrator", "dynamics", "volumetric")


def _value(summary: dict, key: str) -> float:
    """The summary's ``key`` (``name[i]``: entry i of a list), NaN where missing."""
    name, _, index = key.partition("[")
    value = summary.get(name)
    if value is not None and index:
        value = value[int(index.rstrip("]"))]
    return float("nan") if value is None else float(value)


def run_series(series: Series, size, comm: MPI.Comm = MPI.COMM_WORLD) -> dict:
    """One run of ``series`` at ``size``: its row (without the series' fit). Collective."""
    options = {k: v for k, v in series.options.items() if k not in _STEPPING}
    stepping = {k: v for k, v in series.options.items() if k in _STEPPING}
    builder = SCENES[series.scene]
    if "frames" in inspect.signature(builder).parameters:
        options["frames"] = 0
    start = time.perf_counter()
    try:
        scene = builder(**options, **{series.size: size}, comm=comm)
        if stepping:
            scene.options = dataclasses.replace(scene.options, **stepping)
        if series.steps:
            scene.dt = scene.t_end / series.steps
        summary = run_scene(scene, None, progress=False)
        value = _value(summary, series.quantity) * series.scale
    except Exception as e:  # noqa: BLE001 - a run that fails stays a row, with its reason
        summary, value = {"reason": f"{type(e).__name__}: {e}"}, float("nan")
    wall = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
    ref = series.reference
    if isinstance(ref, str):
        ref = _value(summary, ref[1:])
    return {"scene": series.scene, "quantity": series.quantity, "variant": series.variant, "size": size,
            "value": value, "reference": float("nan") if ref is None else float(ref), "error": float("nan"),
            "order": float("nan"), "extrapolated": float("nan"), "wall_s": wall, "reason": summary.get("reason", "")}


def fit(h: np.ndarray, values: np.ndarray, reference: float) -> tuple[float, float]:
    """(order, extrapolated value) of a series of ``values`` at cell sizes ``h`` (coarse to fine;
    see the module). NaN where they cannot be had."""
    ok = np.isfinite(values)
    h, v = np.asarray(h, dtype=float)[ok], np.asarray(values, dtype=float)[ok]
    order = extrapolated = float("nan")
    if np.isfinite(reference) and len(v) >= 2:
        e = np.abs(v - reference)
        if np.all(e > 0):
            order = float(np.polyfit(np.log(h), np.log(e), 1)[0])
    if len(v) >= 3:
        def richardson(a, b, c, ratio):
            if b == a or c == b or (b - a) * (c - b) <= 0:  # not monotone: no asymptotic range
                return float("nan"), float("nan")
            p = math.log(abs(b - a) / abs(c - b)) / math.log(ratio)
            return p, c + (c - b) / (ratio**p - 1.0)

        ratio = h[-2] / h[-1]
        p, x = richardson(*v[-3:], ratio)
        steady = np.isfinite(p) and 0.3 < p < 6.0
        if len(v) >= 4 and steady:
            q, _ = richardson(*v[-4:-1], h[-3] / h[-2])
            steady = np.isfinite(q) and abs(p - q) < 0.5
        if steady:
            extrapolated = x
            if not np.isfinite(reference):
                order = p
    return order, extrapolated


def _finish(rows: list[dict], series: Series) -> None:
    """Each row of ``series``: the series' order and extrapolated value, and its error."""
    mine = [r for r in rows if r["scene"] == series.scene and r["variant"] == series.variant]
    if not mine:
        return
    sizes = np.array([r["size"] for r in mine], dtype=float)
    h = sizes if series.size == "h" else 1.0 / sizes
    values = np.array([r["value"] for r in mine])
    known = [r["reference"] for r in mine if np.isfinite(r["reference"])]
    reference = known[-1] if known else float("nan")  # (a run that failed has no summary to give it)
    order, extrapolated = fit(h, values, reference)
    base = reference if np.isfinite(reference) else extrapolated
    for r in mine:
        r["order"], r["extrapolated"] = order, extrapolated
        if np.isfinite(base):
            r["error"] = (r["value"] - base) / abs(base) if base != 0 else r["value"] - base


def run_study(out: Path = Path("output/study-scenes"), *, quick: bool = False, problems=None,
              provenance: Provenance | None = None, comm: MPI.Comm = MPI.COMM_WORLD) -> list[dict]:
    """Run the series (``problems``: their names, ``scene`` or ``scene/variant``; all by default)
    at their sizes and write the report into ``out``. Collective."""
    names = [n for n in SERIES if problems is None or n in problems or n.split("/")[0] in problems]
    if problems is not None:
        chosen([p for p in problems if p not in SERIES], sorted({s.scene for s in SERIES.values()}), "scene")
    out, provenance = prepare(out, provenance, comm)
    picked = [SERIES[n] for n in names]
    cases = [(s, size) for s in picked for size in (s.quick if quick else s.sizes)]
    rows: list[dict] = []

    def save(done: list[dict]) -> None:
        rows[:] = done
        for s in picked:
            _finish(rows, s)
        write_report(rows, out, provenance)

    sweep(cases, lambda s, size: run_series(s, size, comm), _describe, save, comm)
    return rows


def _describe(row: dict) -> str:
    return (f"{row['scene']:10s} {row['variant']:34s} {row['size']:>6g}: {row['quantity']} = {row['value']:.6g} "
            f"(reference {row['reference']:.6g}) in {row['wall_s']:.1f} s")


def _text(value) -> str:
    if isinstance(value, float):
        return "" if not math.isfinite(value) else f"{value:.6g}"
    return str(value)


def write_report(rows: list[dict], out: Path, provenance: Provenance) -> None:
    """``scenes_convergence.csv``, ``.md`` and a figure per scene into ``out`` (rank 0)."""
    out = Path(out)
    with open(out / "scenes_convergence.csv", "w", newline="") as f:
        w = csv.DictWriter(f, COLUMNS)
        w.writeheader()
        w.writerows({k: _text(r[k]) for k in COLUMNS} for r in rows)
    provenance.write(out)
    lines = ["# Convergence of the scenes' headline numbers", "", provenance.line(), "",
             "| scene | quantity | variant | size | value | reference | error | order | extrapolated | wall (s) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        error = f"{100 * r['error']:+.3g} %" if math.isfinite(r["error"]) else ""
        lines.append(f"| {r['scene']} | {r['quantity']} | {r['variant']} | {_text(r['size'])} | {_text(r['value'])} | "
                     f"{_text(r['reference'])} | {error} | {_text(r['order'])} | {_text(r['extrapolated'])} | "
                     f"{r['wall_s']:.1f} |")
    failed = [r for r in rows if r["reason"]]
    with open(out / "scenes_failures.csv", "w", newline="") as f:
        w = csv.DictWriter(f, ["scene", "variant", "size", "reason"])
        w.writeheader()
        w.writerows({k: _text(r[k]) for k in ("scene", "variant", "size", "reason")} for r in failed)
    if failed:
        lines += ["", "Runs that failed:", ""]
        lines += [f"- {r['scene']} {r['variant']} at {_text(r['size'])}: {r['reason']}" for r in failed]
    (out / "scenes_convergence.md").write_text("\n".join(lines) + "\n")
    _figures(rows, out)


def _figures(rows: list[dict], out: Path) -> None:
    """``scenes_<scene>.png``: |error| against the cell size, one line per series."""
    for scene in dict.fromkeys(r["scene"] for r in rows):
        series = []
        for variant in dict.fromkeys(r["variant"] for r in rows if r["scene"] == scene):
            mine = [r for r in rows if r["scene"] == scene and r["variant"] == variant and math.isfinite(r["error"])
                    and r["error"] != 0]
            by_length = SERIES[f"{scene}/{variant}"].size == "h"
            if mine:
                series.append((variant, [r["size"] if by_length else 1.0 / r["size"] for r in mine],
                               [abs(r["error"]) for r in mine]))
        plot_errors(out / f"scenes_{scene}.png", series, xlabel="h (cell size, or 1 / cells)",
                    ylabel="|error| (relative; absolute against 0)", title=scene)
