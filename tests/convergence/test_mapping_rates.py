"""The mapping study at a small size: files written, FE fields reproduced, fitted L2 rates."""

import pytest
from mpi4py import MPI

from fempm.studies import mapping


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("study")
    rows = mapping.run(sizes=(8, 16, 32), ppcs=(4,), out=out, log=lambda *a: None)
    return rows, out


def test_study_writes_table_and_plot(study):
    rows, out = study
    if MPI.COMM_WORLD.rank == 0:
        assert (out / "mapping.png").stat().st_size > 20_000
        assert len((out / "mapping.csv").read_text().splitlines()) == len(rows) + 1
        assert "Fitted convergence rates" in (out / "mapping.md").read_text()


def test_fe_field_reproduced_by_consistent_only(study):
    rows, _ = study
    fe = [r for r in rows if r["field"] == "fe"]
    assert all(r["l2_error"] < 1e-10 for r in fe if r["mass"] == "consistent")
    assert all(r["l2_error"] > 1e-3 for r in fe if r["mass"] == "lumped")


def test_fitted_rates(study):
    rows, _ = study
    rates = {(r["mesh"], r["space"], r["mass"]): r["rate"] for r in mapping.convergence_rates(rows)}
    for mesh in mapping.MESH_KINDS:
        assert rates[mesh, "P1", "consistent"] == pytest.approx(2.0, abs=0.2)
        assert 1.2 < rates[mesh, "P1", "lumped"] < 1.9  # lumping costs accuracy on jittered particles
    for mesh in ("structured-tri", "unstructured-tri"):
        assert rates[mesh, "P2", "consistent"] == pytest.approx(3.0, abs=0.25)
