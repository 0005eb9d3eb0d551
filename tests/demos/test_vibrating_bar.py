"""Vibrating bar against the exact solution (docs/verification.md)."""

import numpy as np
import pytest
from test_demos import load

bar = load("vibrating_bar")


def test_usl_flip_16_cells_consistent_within_2_5_percent(tmp_path):
    r = bar.main(["--cells", "16", "--mass", "consistent", "--out", str(tmp_path), "--no-plot"])
    assert r["vcm_error"] < 0.025
    assert r["energy_error"] < 5e-3


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_bar_converges_under_refinement(tmp_path, mass):
    cells = [8, 16, 32]
    rs = [bar.main(["--cells", str(n), "--mass", mass, "--out", str(tmp_path / str(n)), "--no-plot"]) for n in cells]
    vcm = [r["vcm_error"] for r in rs]
    rate = -np.polyfit(np.log(cells), np.log(vcm), 1)[0]
    assert vcm[0] > vcm[1] > vcm[2] and rate > 1.0, (vcm, rate)
    if mass == "lumped":
        energy = [r["energy_error"] for r in rs]
        assert energy[0] > energy[1] > energy[2], energy


def test_2d_strip_reproduces_the_1d_bar(tmp_path):
    """nu = 0, one cell high: the strip's centre-of-mass velocity is the 1D one to round-off."""
    args = ["--cells", "16", "--mass", "lumped", "--t-end", "10", "--no-plot"]
    r1 = bar.main(args + ["--out", str(tmp_path / "1d")])
    r2 = bar.main(args + ["--out", str(tmp_path / "2d"), "--dim", "2"])
    np.testing.assert_allclose(r2["t"], r1["t"], rtol=1e-12)
    np.testing.assert_allclose(r2["vcm"], r1["vcm"], atol=1e-12)
    assert r2["energy_error"] == pytest.approx(r1["energy_error"], rel=1e-8)
