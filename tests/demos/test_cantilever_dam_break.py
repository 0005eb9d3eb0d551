"""Cantilever against Euler-Bernoulli (docs/verification.md) and dam break against Martin
and Moyce (section 9), at the demos' default resolution."""

import numpy as np
import pytest
from test_demos import load

cantilever = load("cantilever")
dam = load("dam_break")


def test_cantilever_time_averaged_tip_deflection_within_5_percent(tmp_path):
    r = cantilever.main(["--cells", "4", "--periods", "1", "--out", str(tmp_path), "--no-plot"])
    assert abs(r["tip_error"]) < 0.05, r["tip_error"]  # measured: +0.1 %
    assert 1.7 < r["tip_max"] / r["reference_at_x_tip"] < 2.05  # suddenly applied load: swings to ~2 delta
    # gravity is the only load: the body force is assembled every step, traction never
    assert r["terms_assembled"] == {"internal": r["steps"], "body_force": r["steps"]}


def test_dam_break_front_converges_ahead_of_martin_moyce(tmp_path):
    coarse = dam.main(["--cells", "10", "--out", str(tmp_path / "10"), "--no-plot"])
    fine = dam.main(["--cells", "20", "--out", str(tmp_path / "20"), "--no-plot"])
    T = np.array(fine["T"])
    late = T >= 2.0
    dev = np.array(fine["deviation"])[late]
    # the experiment lags an inviscid simulation (gate lift, floor friction): measured +8..+12 %
    assert np.all(dev > 0.0) and np.all(dev < 0.15), dev
    np.testing.assert_allclose(coarse["Z_fempm"], fine["Z_fempm"], rtol=0.05)  # measured: < 3.4 %
    assert fine["mass_defect"] < 1e-13


@pytest.mark.slow  # 20 s: make test-all
def test_cantilever_with_particle_domains_runs_pure_flip(tmp_path):
    """GIMP and CPDI1 remove the cell-crossing noise that makes the point basis need 5 % PIC:
    pure FLIP over a full period, within 5 % at two cells through the thickness (measured
    GIMP -1.5 %, CPDI1 -2.0 %; the point basis with flip 0.95 gives -3.8 % here)."""
    for domain in ("gimp", "cpdi1"):
        r = cantilever.main(["--cells", "2", "--periods", "1", "--flip", "1.0", "--domain", domain,
                             "--out", str(tmp_path / domain), "--no-plot"])
        assert abs(r["tip_error"]) < 0.05, (domain, r["tip_error"])
        assert 1.8 < r["tip_max"] / r["reference_at_x_tip"] < 2.1, (domain, r["tip_max"])
