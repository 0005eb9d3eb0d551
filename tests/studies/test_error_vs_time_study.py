"""The error-against-run-time study at --quick size (fempm.studies.error_vs_time): the fixed
CSV columns, a correct Pareto front per problem, the report and the figures."""

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import quick_study
from mpi4py import MPI

from fempm.studies import error_vs_time as evt

# one worker computes its module fixtures; the whole quick study takes 30 s: make test-all
pytestmark = [pytest.mark.xdist_group("test_error_vs_time_study"), pytest.mark.slow]


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    return quick_study(tmp_path_factory, "evt", evt.run_study)


def test_csv_has_the_fixed_columns_and_every_run(study):
    out, rows = study
    expected = sum(len(s.quick_configs) * len(s.quick_sizes) for s in evt.SWEEPS.values())
    assert len(rows) == expected
    if MPI.COMM_WORLD.rank == 0:
        with open(Path(out) / "error_vs_time.csv", newline="") as f:
            reader = csv.DictReader(f)
            assert reader.fieldnames == ["problem", "mesh", "degree", "mass", "domain", "scheme", "cells", "ppc", "error",
                                         "wall_s", "repeats", "threads", "pareto", "integration", "transfer"]
            assert len(list(reader)) == expected
        assert (Path(out) / "error_vs_time.md").read_text().count("## ") == len(evt.SWEEPS)
        assert (Path(out) / "error_vs_time.md").read_text().splitlines()[2].startswith("Made by `")
        assert set(json.loads((Path(out) / "provenance.json").read_text())) == {"commit", "command", "date", "ranks"}
        for problem in evt.SWEEPS:
            assert (Path(out) / f"error_vs_time_{problem}.png").stat().st_size > 10_000


def test_runs_are_finite_and_timed(study):
    _, rows = study
    for r in rows:
        assert np.isfinite(r["error"]) and r["error"] > 0 and r["wall_s"] > 0, r
        assert r["repeats"] in (1, 3) and r["threads"] >= 1


def test_pareto_front_is_exactly_the_non_dominated_rows(study):
    _, rows = study
    for problem in evt.SWEEPS:
        rs = [r for r in rows if r["problem"] == problem]
        for r in rs:
            dominated = any(o is not r and o["error"] <= r["error"] and o["wall_s"] <= r["wall_s"]
                            and (o["error"] < r["error"] or o["wall_s"] < r["wall_s"]) for o in rs)
            assert r["pareto"] == (not dominated), (problem, r)
        assert any(r["pareto"] for r in rs)


def test_consistent_and_fmpm_beat_lumped_mapping_error(study):
    """At equal resolution, the consistent projection of a smooth field is more accurate than
    FMPM(3), which is more accurate than the lumped one."""
    _, rows = study
    for cells in (8, 16):
        e = {r["mass"]: r["error"] for r in rows if r["problem"] == "mapping" and r["cells"] == cells}
        assert e["consistent"] < e["fmpm3"] < e["lumped"]


def test_implicit_rows(study):
    """Cook's membrane at 6 cells across: the quasi-static implicit runs (1 and 10 load steps)
    find the explicit damped run's rest state (errors about 0.109 against the reference: the P1
    answer on that mesh); the compaction column's stress error falls under refinement
    (0.101 -> 0.046, cpGIMP); Newmark's bar at Courant 4 is a row of the bar."""
    _, rows = study
    cook = {r["integration"]: r["error"] for r in rows if r["problem"] == "cook"}
    assert set(cook) == {"explicit", "quasi-static 1 step(s)", "quasi-static 10 step(s)"}
    for name in ("quasi-static 1 step(s)", "quasi-static 10 step(s)"):
        assert abs(cook[name] - cook["explicit"]) < 5e-3, cook
    compaction = {r["cells"]: r["error"] for r in rows if r["problem"] == "compaction"}
    assert compaction[8] < 0.6 * compaction[4], compaction
    assert [r["integration"] for r in rows if r["problem"] == "vibrating_bar" and r["integration"] != "explicit"] == [
        "newmark courant=4"] * 2
