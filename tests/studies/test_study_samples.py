"""One sample of each long study in the default run (the whole quick studies run in
``make test-all``: tests/studies/test_convergence_study.py, test_stability_study.py): the
convergence study on the vibrating bar, the stability catalogue on its one-particle-per-cell case."""

import csv

import numpy as np
import pytest
from conftest import shared_tmp

from fempm.studies import convergence, stability


def test_the_convergence_study_of_the_vibrating_bar(tmp_path_factory):
    out = shared_tmp(tmp_path_factory, "convergence-bar")
    rows = convergence.run(out, quick=True, problems=["vibrating_bar"], log=lambda *a: None)
    spec = convergence.PROBLEMS["vibrating_bar"]
    assert len(rows) == len(spec.quick_configs) * len(spec.quick_sizes)
    assert all(r["status"] == "ok" for r in rows)
    with open(f"{out}/convergence.csv") as f:
        table = list(csv.DictReader(f))
    assert list(table[0]) == convergence.COLUMNS and len(table) == len(rows)
    for mass in ("lumped", "consistent"):  # point particles: the error falls, then stalls at the cell-crossing error
        e = [r["error_l2"] for r in sorted((r for r in rows if r["mass"] == mass), key=lambda r: r["cells"])]
        assert e[-1] < e[0] and np.all(np.isfinite(e)), (mass, e)


@pytest.mark.slow  # 16 s; the whole quick catalogue runs in make test-all (test_stability_study.py)
def test_the_stability_catalogue_of_one_particle_per_cell(tmp_path_factory):
    """ppc = 1: USL with point particles blows up, MUSL and the particle domains stay stable
    (docs/error-vs-time-and-stability.md); every option a row with a known cause."""
    out = shared_tmp(tmp_path_factory, "stability-ppc1")
    rows = stability.run_study(out, quick=True, cases=["ppc=1"], log=lambda *a: None)
    assert [r["option"] for r in rows] == [stability.label(o) for o in stability.options_for("ppc=1", quick=True)]
    outcome = {r["option"].split(" cut=")[0]: r["outcome"] for r in rows}
    assert outcome["USL lumped point"] == "unstable" and outcome["MUSL lumped point"] == "stable"
    assert outcome["USL lumped gimp"] == "stable" and outcome["USL lumped cpdi1"] == "stable"
    for r in rows:
        if r["outcome"] == "unstable":
            assert "energy growth" in r["reason"] and r["energy_ratio"] > 1.0, r
    with open(f"{out}/stability.csv", newline="") as f:
        assert len(list(csv.DictReader(f))) == len(rows)
