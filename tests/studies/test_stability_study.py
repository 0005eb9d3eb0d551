"""The stability catalogue at --quick size (fempm.studies.stability): a row for every option of
every case, finite figures where stable, known causes where not, and no Python traceback."""

import csv
import json

import numpy as np
import pytest
from conftest import quick_study

from fempm.studies import stability
from fempm.studies.stability_cases import CASES

# one worker computes its module fixtures; the whole quick catalogue (2 minutes) in make test-all,
# one case in the default run (tests/studies/test_study_samples.py)
pytestmark = [pytest.mark.xdist_group("test_stability_study"), pytest.mark.slow]


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    return quick_study(tmp_path_factory, "stability", stability.run_study)


def test_every_case_has_a_row_for_every_option(study):
    out, rows = study
    for case in CASES:
        assert [r["option"] for r in rows if r["case"] == case] == [stability.label(o) for o in stability.options_for(case, quick=True)]
    with open(f"{out}/stability.csv", newline="") as f:
        reader = csv.DictReader(f)
        assert reader.fieldnames == ["case", "option", "outcome", "reason", "energy_ratio", "momentum_drift", "j_min",
                                     "j_max", "steps", "wall_s"]
        assert len(list(reader)) == len(rows)
    md = open(f"{out}/stability.md").read()
    assert all(f"## {case}" in md for case in CASES)
    assert md.splitlines()[2].startswith("Made by `")
    assert set(json.loads(open(f"{out}/provenance.json").read())) == {"commit", "command", "date", "ranks"}


def test_stable_rows_are_finite_and_within_the_limits(study):
    _, rows = study
    stable = [r for r in rows if r["outcome"] == "stable"]
    assert len(stable) >= len(rows) // 3
    for r in stable:
        figures = [r[k] for k in ("energy_ratio", "momentum_drift", "j_min", "j_max", "wall_s")]
        assert np.all(np.isfinite(figures)), r
        assert r["energy_ratio"] <= 1.2 and 1e-2 <= r["j_min"] <= r["j_max"] <= 1e2 and r["steps"] > 0, r
        assert r["reason"] == ""


def test_failures_name_their_cause(study):
    _, rows = study
    for r in rows:
        assert r["outcome"] in stability.OUTCOMES
        if r["outcome"] == "unstable":
            assert "energy growth" in r["reason"] and r["energy_ratio"] > 1.0, r
        if r["outcome"] == "aborted":
            assert r["reason"].split(":")[0] in ("SimulationError", "SingularMassError", "OutsideMeshError", "ValueError"), r
        if r["outcome"] == "refused":  # the configuration does not take the option: no step was run
            assert r["reason"].split(":")[0] in ("ValueError", "TypeError") and r["steps"] == 0, r


def test_catalogue_findings(study):
    """What the catalogue shows at this size, asserted so that a regression is seen: USL with
    point particles blows up where a particle column sits next to nearly empty nodes, the
    averaged domains survive near-incompressibility, a CFL number of 1 is not stable for USL,
    and the long run stays stable with the default options."""
    _, rows = study
    get = {(r["case"], r["option"]): r for r in rows}
    base = stability.label({})
    assert get["near-empty-cells", base]["outcome"] != "stable"
    assert get["nu=0.4999", stability.label({"domain": "cpdi1"})]["outcome"] == "stable"
    assert get["cfl", stability.label({"cfl": 1.0})]["outcome"] != "stable"
    assert get["long-run", base]["outcome"] == "stable"
    assert get["high-velocity", base]["reason"].startswith("SimulationError") and "J = det F" in get["high-velocity", base]["reason"]
    # plasticity dissipates: the column's potential energy released and the disks' kinetic
    # energy end mostly as plastic work (and floor friction), whatever the option
    for r in rows:
        if r["case"] in ("column-collapse", "plastic-impact") and r["outcome"] == "stable":
            assert r["energy_ratio"] < (0.35 if r["case"] == "column-collapse" else 0.75), r
    assert get["column-collapse", base]["outcome"] == "stable"
    assert get["plastic-impact", stability.label({"scheme": "MUSL"})]["outcome"] == "stable"
    # contact: the disks and the impact are stable with lumped and consistent mass, the impact
    # keeps J above 0.4 (one field crushes the interface), USF is refused by name
    for case in ("contact-disks", "contact-impact"):
        for opts in ({}, {"mass": "consistent"}, {"domain": "gimp"}):
            assert get[case, stability.label(opts)]["outcome"] == "stable", (case, opts)
        assert "USL and MUSL" in get[case, stability.label({"scheme": "USF"})]["reason"]
    assert get["contact-impact", base]["j_min"] > 0.4
    assert get["contact-rolling", stability.label({"scheme": "MUSL"})]["outcome"] == "stable"
