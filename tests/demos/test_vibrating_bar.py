"""Vibrating bar against the exact solution (VERIFICATION.md section 1)."""

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
