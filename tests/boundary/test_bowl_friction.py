"""A disk released in a circular bowl whose arc is a tagged frictional wall (the ``bowl`` scene,
mu = 0.3): with pure FLIP the run gains energy and stops on the energy check, whose message
names the cause and the blend that keeps it (docs/boundaries.md, "Friction on a curved wall");
with that blend it runs to the end within its energy budget, on 1 and 2 ranks, and rolls."""

import numpy as np
import pytest

import fempm  # noqa: F401  (before dolfinx)
from fempm.scene import run
from fempm.scenes import bowl
from fempm.scenes.bowl import pendulum_period
from fempm.scenes.periods import crossing_period
from fempm.stepping import SimulationError


def test_pure_flip_on_a_curved_frictional_wall_stops_naming_the_blend():
    with pytest.raises(SimulationError, match=r"energy growth.*pure FLIP \(flip = 1\) gains energy where a body "
                                              r"rolls or slides along a curved wall.*flip = 0.99"):
        run(bowl(cells=4, wall="friction", frames=0), progress=False)


@pytest.mark.parallel
def test_a_blend_keeps_the_rolling_disk_in_its_energy_budget():
    summary = run(bowl(cells=4, wall="friction", flip=0.95, periods=1.0, frames=0), progress=False)
    h = summary["health"]
    assert summary["status"] == "completed" and h["energy_ratio"] < 1.0  # rolling and sliding lose energy
    assert summary["energy_ratio"] < 1.0 and h["momentum_drift"] < 1e-11  # the wall's reactions counted


def test_the_pendulum_reference():
    """K(m) by the AGM against its power series: the period at 30 degrees is 1.0174 times the
    small-amplitude one; the zero crossings of a sampled cosine give its period."""
    m = np.sin(np.radians(15.0)) ** 2
    coefficients = np.cumprod([1.0] + [((2 * n - 1) / (2 * n)) ** 2 for n in range(1, 60)])
    K = 0.5 * np.pi * np.sum(coefficients * m ** np.arange(60))
    assert pendulum_period(0.8, 10.0, np.radians(30.0)) == pytest.approx(4 * np.sqrt(0.08) * K, rel=1e-12)
    assert pendulum_period(0.8, 10.0, np.radians(30.0)) / (2 * np.pi * np.sqrt(0.08)) == pytest.approx(1.0174, abs=1e-4)
    assert pendulum_period(1.0, 9.81, 1e-8) == pytest.approx(2 * np.pi / np.sqrt(9.81), rel=1e-12)
    t = np.linspace(0.0, 5.0, 5001)
    assert crossing_period(t, np.cos(2 * np.pi * t / 1.3)) == pytest.approx(1.3, rel=1e-6)
    assert np.isnan(crossing_period(t[:10], np.cos(t[:10])))


def test_bad_bowls_are_named():
    with pytest.raises(ValueError, match="unknown wall='sticky'"):
        bowl(wall="sticky")
    with pytest.raises(ValueError, match="release=90 must lie in"):
        bowl(release=90.0)
    with pytest.raises(ValueError, match="radius=0.6 must be below half"):
        bowl(radius=0.6)
