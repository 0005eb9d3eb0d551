"""The convergence study of the MPM loop at --quick size (fempm.studies.convergence): fitted
rates of the manufactured solutions, failures kept as rows with their reasons."""

import csv

import numpy as np
import pytest
from mpi4py import MPI

from fempm.studies import convergence

# one worker computes its module fixtures; the whole quick study (3 minutes with its kernels) in
# make test-all, one problem in the default run (tests/studies/test_study_samples.py)
pytestmark = [pytest.mark.xdist_group("test_convergence_study"), pytest.mark.slow]


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("convergence") if MPI.COMM_WORLD.rank == 0 else None
    out = MPI.COMM_WORLD.bcast(str(out), root=0)
    rows = convergence.run(out, quick=True, log=lambda *a: None)
    return out, rows, {(r["problem"], r["mesh"], r["degree"], r["variant"], r["mass"], r["domain"], r["scheme"]): r
                       for r in convergence.fitted_rates(rows)}


def rate(rates, problem, domain, mass="lumped", mesh="interval", scheme="USL"):
    return rates[problem, mesh, 1, "default", mass, domain, scheme]


def test_table_has_every_run_with_the_fixed_columns(study):
    out, rows, _ = study
    expected = sum(len(s.quick_configs) * len(s.quick_sizes) for s in convergence.PROBLEMS.values())
    assert len(rows) == expected
    if MPI.COMM_WORLD.rank == 0:
        with open(f"{out}/convergence.csv") as f:
            table = list(csv.DictReader(f))
        assert list(table[0]) == convergence.COLUMNS == [
            "problem", "mesh", "degree", "variant", "mass", "domain", "scheme", "cells", "h", "dt", "steps",
            "error_max", "error_rms", "error_l2", "wall_s", "status"]
        assert len(table) == expected
        for r in table:
            assert r["status"] == "ok" or r["status"].endswith("Error")
            if r["status"] == "ok":
                assert all(np.isfinite(float(r[k])) for k in ("h", "dt", "error_max", "error_rms", "error_l2", "wall_s"))
        md = open(f"{out}/convergence.md").read()
        assert "| rate L2 |" in md
        for name in convergence.PROBLEMS:
            assert (convergence.Path(out) / f"convergence_{name}.png").stat().st_size > 10_000


def test_small_deformation_point_mpm_is_second_order(study):
    """1D solution at G = 1e-4, 8 to 64 cells: rate >= 1.9 with lumped and with consistent mass."""
    _, _, rates = study
    for mass in ("lumped", "consistent"):
        r = rate(rates, "axis_aligned_1d_G1e-4", "point", mass)
        assert r["rate_l2"] >= 1.9 and r["rate_max"] >= 1.9, r


def test_large_deformation_needs_domains(study):
    """1D solution at G = 0.05, 16 to 128 cells: exact cpGIMP, CPDI1 and CPDI2 converge at rate
    >= 1.8 over the 4 sizes, point MPM does not converge (particles cross cells)."""
    _, rows, rates = study
    for domain in ("cpgimp", "cpdi1", "cpdi2"):
        rs = sorted((r for r in rows if r["problem"] == "axis_aligned_1d_G0.05" and r["domain"] == domain),
                    key=lambda r: r["cells"])
        assert [r["cells"] for r in rs] == [16, 32, 64, 128] and all(r["status"] == "ok" for r in rs)
        fit = np.polyfit(np.log([r["h"] for r in rs]), np.log([r["error_l2"] for r in rs]), 1)[0]
        assert fit >= 1.8, (domain, fit)
    point = rate(rates, "axis_aligned_1d_G0.05", "point")
    assert point["verdict"] == "not converging" and point["rate_l2"] < 0
    ugimp = rate(rates, "axis_aligned_1d_G0.05", "ugimp")
    assert ugimp["verdict"] != "converging" or ugimp["rate_l2"] < 1.5  # boxes of the initial size leave gaps


def test_vortex_errors_decrease_and_failures_say_why(study):
    _, rows, _ = study

    def errors(problem, domain):
        rs = sorted((r for r in rows if r["problem"] == problem and r["domain"] == domain), key=lambda r: r["cells"])
        return [r["error_l2"] for r in rs], [r["status"] for r in rs]

    for domain in ("point", "cpdi2"):
        e, status = errors("vortex_A0.01", domain)
        assert status == ["ok", "ok"] and e[1] < 0.5 * e[0]
    e, status = errors("vortex_A1", "cpdi1")  # large shear: CPDI1 runs to t = 1
    assert status == ["ok", "ok"] and e[1] < 0.5 * e[0]
    # CPDI2 on 24 cells: its corners, moved with the grid velocity, invert a domain thinned ~9x by the shear
    _, status = errors("vortex_A1", "cpdi2")
    assert status == ["SimulationError", "ok"]
    bad = next(r for r in rows if r["problem"] == "vortex_A1" and r["domain"] == "cpdi2" and r["cells"] == 24)
    assert "inverted particle domain" in bad["reason"] and bad["steps"] > 0


def test_plastic_impact_converges(study):
    """The J2 strip hitting a wall (fempm.verification.plastic_impact): the two-wave exact solution is
    approached under refinement, lumped and consistent, at about h^(1/2) (the velocity jumps
    at both fronts)."""
    _, rows, _ = study
    for mass in ("lumped", "consistent"):
        rs = sorted((r for r in rows if r["problem"] == "plastic_impact" and r["mass"] == mass), key=lambda r: r["cells"])
        assert [r["cells"] for r in rs] == [16, 32, 64] and all(r["status"] == "ok" for r in rs)
        e = [r["error_l2"] for r in rs]
        assert e[2] < e[1] < e[0] < 2e-5, (mass, e)
        rate = np.polyfit(np.log([r["h"] for r in rs]), np.log(e), 1)[0]
        assert 0.3 < rate < 1.5, (mass, rate)
