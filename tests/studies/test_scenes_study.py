"""The scenes convergence study (fempm.studies.scenes): the fitted order and Richardson's
extrapolation on series of known order, the CSV's columns, and a quick run of cheap scenes
whose errors fall under refinement."""

import csv
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from fempm.cli import main
from fempm.studies.scenes import COLUMNS, COOK_FE, SERIES, fit


def test_the_order_with_a_reference_is_the_slope_of_the_errors():
    h = np.array([1 / 8, 1 / 16, 1 / 32, 1 / 64])
    order, extrapolated = fit(h, 3.0 + 0.7 * h**2, 3.0)
    assert order == pytest.approx(2.0, abs=1e-12)
    assert extrapolated == pytest.approx(3.0, abs=1e-12)  # steady order: Richardson's value


def test_without_a_reference_richardson_finds_the_limit_and_its_order():
    h = np.array([0.4, 0.2, 0.1, 0.05])
    order, extrapolated = fit(h, 3.0 - 2.0 * h**1.5, np.nan)
    assert order == pytest.approx(1.5, abs=1e-12) and extrapolated == pytest.approx(3.0, abs=1e-12)
    # not monotone (no asymptotic range) or an order that changes: no extrapolation
    assert np.isnan(fit(h, np.array([1.0, 1.2, 1.1, 1.15]), np.nan)[1])
    assert np.isnan(fit(h, np.array([1.0, 1.5, 1.6, 1.61]), np.nan)[1])


def test_the_study_covers_every_scene_with_a_reference_at_four_sizes():
    scenes = {s.scene for s in SERIES.values()}
    assert {"cook", "bar", "compaction", "wave", "incline", "footing", "silo", "column", "bowl"} <= scenes
    assert all(len(s.sizes) >= 4 for s in SERIES.values())
    assert COOK_FE[1 / 3] == pytest.approx(22.611, abs=2e-3)


def test_a_quick_run_writes_the_table_and_the_errors_fall(tmp_path):
    out = Path(MPI.COMM_WORLD.bcast(str(tmp_path), root=0)) / "scenes"
    assert main(["study", "scenes", "--quick", "--problems", "bar", "wave/absorbing", "--out", str(out)]) == 0
    if MPI.COMM_WORLD.rank == 0:
        with open(out / "scenes_convergence.csv", newline="") as f:
            reader = csv.DictReader(f)
            assert reader.fieldnames == COLUMNS
            rows = list(reader)
        assert [(r["scene"], r["variant"], r["size"]) for r in rows] == [
            ("bar", "explicit MUSL", "8"), ("bar", "explicit MUSL", "16"), ("bar", "Newmark", "8"),
            ("bar", "Newmark", "16"), ("wave", "absorbing", "32"), ("wave", "absorbing", "64")]
        for a, b in zip(rows[::2], rows[1::2]):
            assert abs(float(b["error"])) < abs(float(a["error"]))
            assert float(a["order"]) > 1.0  # the bar's period: about 2; the absorbed pulse: 3.6
        assert (out / "scenes_bar.png").exists() and "Made by" in (out / "scenes_convergence.md").read_text()


def test_an_unknown_scene_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as e:
        main(["study", "scenes", "--quick", "--problems", "teapot", "--out", "unused"])
    assert e.value.code == 2 and "unknown scene 'teapot'" in capsys.readouterr().err


def test_a_run_that_fails_stays_a_row_with_its_reason():
    from fempm.studies.scenes import Series, run_series

    row = run_series(Series("bar", "period", "too large a step", "cells", (8,), (8,), {"cfl": 2.0}, 10.0), 8)
    assert np.isnan(row["value"]) and "cfl" in row["reason"].lower()
