"""The footing scene (fempm.scenes.footing): a rigid strip footing (a box collider) pushed into a
weightless von Mises layer reaches Prandtl's bearing pressure (2 + pi) c within 15 % at 16 cells
across it (docs/colliders.md has 8 to 32 cells: 1.02 at 32); the reaction rises from 0 with the
penetration; bad options named."""

import numpy as np
import pytest

from fempm.scene import run
from fempm.scenes.footing import footing, prandtl


def test_the_footing_reaches_prandtls_pressure():
    """12 cells: 1.034 of Prandtl (8: 1.298; the series to 32 cells: docs/colliders.md)."""
    scene = footing(cells=12)
    pressure = []
    summary = run(scene, None, progress=False, callback=lambda s: pressure.append(s.collisions.force[0][1]))
    c = scene.params["yield_stress"] / np.sqrt(3.0)
    assert summary["prandtl"] == pytest.approx((2.0 + np.pi) * c, rel=1e-12)
    assert summary["bearing_pressure"] == pytest.approx(summary["prandtl"], rel=0.15)
    assert summary["penetration"] == pytest.approx(0.1, rel=1e-6)
    assert summary["colliders"][0]["displacement"] == pytest.approx([0.0, -0.1], abs=1e-9)
    early = np.mean(pressure[: len(pressure) // 50])  # the elastic start, far below the limit
    assert 0.0 <= early < 0.2 * summary["prandtl"]


def test_bad_footing_options_are_named():
    with pytest.raises(ValueError, match=r"depth=0 must lie in \(0, 1\]"):
        footing(depth=0)
    with pytest.raises(ValueError, match=r"speed=-1 must be > 0"):
        footing(speed=-1.0)
    assert prandtl(np.sqrt(3.0)) == pytest.approx(2.0 + np.pi)


@pytest.mark.slow
def test_fbar_footing_with_16_particles_a_cell_converges_to_prandtl():
    """F-bar's patch average integrated by 16 particles a cell: 1.187 and 0.976 of Prandtl at 8
    and 16 cells (0.988 at 32, docs/colliders.md); with 4 a cell it levels 7.6 % below."""
    from fempm.stepping import StepOptions

    errors = []
    for cells in (8, 16):
        scene = footing(cells=cells, ppc=16)
        scene.options = StepOptions(scheme="MUSL", flip=0.95, volumetric="fbar")
        errors.append(abs(run(scene, None, progress=False)["bearing_ratio"] - 1.0))
    assert errors[1] < 0.3 * errors[0] and errors[1] < 0.03, errors
