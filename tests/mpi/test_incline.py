"""The incline scene (fempm.scenes.incline): a block slides with g (sin(theta) - mu cos(theta))
within 2 % at two resolutions and sticks where mu > tan(theta); the CLI writes both figures."""

import json

import numpy as np
import pytest
from mpi4py import MPI

from fempm.scene import run
from fempm.scenes.incline import analytic_acceleration, incline


@pytest.mark.parametrize("mu", [0.0, 0.2])
def test_a_block_slides_with_the_analytic_acceleration(mu):
    g_sin = 9.81 * np.sin(np.radians(30.0))
    for cells in (4, 8):
        summary = run(incline("block", 30.0, mu, cells=cells, frames=0), progress=False)
        assert summary["analytic"] == pytest.approx(g_sin - mu * 9.81 * np.cos(np.radians(30.0)), rel=1e-14)
        assert summary["acceleration"] == pytest.approx(summary["analytic"], rel=0.02), cells


def test_a_block_sticks_above_the_friction_angle():
    summary = run(incline("block", 30.0, 1.0, cells=4, frames=0), progress=False)
    assert summary["analytic"] == 0.0
    assert abs(summary["acceleration"]) < 0.02 * 9.81 * np.sin(np.radians(30.0))


def test_analytic_accelerations():
    g = 9.81
    th = np.radians(30.0)
    assert analytic_acceleration("block", 30.0, 0.7) == 0.0
    assert analytic_acceleration("disk", 30.0, 0.2) == pytest.approx(2 / 3 * g * np.sin(th), rel=1e-14)  # rolls
    assert analytic_acceleration("disk", 30.0, 0.1) == pytest.approx(g * (np.sin(th) - 0.1 * np.cos(th)), rel=1e-14)


def test_cli_writes_acceleration_and_analytic(tmp_path):
    from fempm.cli import main

    out = MPI.COMM_WORLD.bcast(str(tmp_path), root=0)
    assert main(["run", "incline", "--body", "block", "--angle", "20", "--friction", "0.1", "--cells", "4",
                 "--out", out + "/run"]) == 0
    summary = json.load(open(out + "/run/summary.json"))
    assert summary["acceleration"] == pytest.approx(summary["analytic"], rel=0.02)
    with pytest.raises(ValueError, match="unknown option body"):
        incline(body="sphere")
