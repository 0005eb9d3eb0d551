"""The exact elastic-plastic impact (fempm.verification.plastic_impact): its motion is consistent (finite
differences, the wall, the jump conditions) and its states are those the J2 law gives."""

import numpy as np
import pytest

from fempm.verification.plastic_impact import PlasticImpact


def test_motion_is_continuous_at_rest_on_the_wall_and_differentiates_to_its_velocity_and_F():
    pr = PlasticImpact()
    t = 0.7 * pr.t_end
    X = np.column_stack([np.linspace(0.0, 1.0, 2001), np.full(2001, 0.1)])
    u = pr.displacement(X, t)
    assert u[0, 0] == pytest.approx(0.0, abs=1e-15) and np.all(u[:, 1] == 0.0)
    assert np.max(np.abs(np.diff(u[:, 0]))) < 1e-5  # continuous (a step of X is 5e-4)
    # away from the fronts: velocity and F by central differences
    fronts = np.array([pr.c_p * t, pr.c_e * t])
    away = np.min(np.abs(X[:, :1] - fronts), axis=1) > 2e-3
    dt, dX = 1e-9, 1e-6
    v = (pr.displacement(X, t + dt) - pr.displacement(X, t - dt)) / (2 * dt)
    np.testing.assert_allclose(v[away], pr.velocity(X, t)[away], rtol=0, atol=1e-9)
    dudX = (pr.displacement(X + [dX, 0], t) - pr.displacement(X - [dX, 0], t))[:, 0] / (2 * dX)
    np.testing.assert_allclose(1.0 + dudX[away], pr.deformation_gradient(X, t)[away, 0, 0], rtol=0, atol=1e-9)
    # momentum balance across each front: rho c [v] = -[sigma] with the small-strain stresses
    lam, mu = pr.lame
    eps2, v2, eps3 = pr.states
    s2 = -pr.hel
    s3 = s2 + (lam + 2 * mu / 3) * (eps3 - eps2)
    assert pr.rho0 * pr.c_e * (v2 - (-pr.v0)) == pytest.approx(-(s2 - 0.0), rel=1e-12)
    assert pr.rho0 * pr.c_p * (0.0 - v2) == pytest.approx(-(s3 - s2), rel=1e-12)


def test_the_states_are_those_of_the_von_mises_law_in_uniaxial_strain():
    """Driving VonMises through uniaxial strain to eps2 and eps3 in small increments gives
    sigma_xx = -sigma_HEL at eps2 (on the yield surface) and -sigma_HEL + K (eps3 - eps2) at
    eps3, up to the finite-strain difference (relative: of the order of the strain)."""
    pr = PlasticImpact()
    law = pr.material
    eps2, _, eps3 = pr.states
    lam, mu = pr.lame
    sigma = np.zeros((1, 2, 2))
    state = {h.name: np.full((1,) + h.shape, h.initial, dtype=float) for h in law.history}
    F = np.eye(2)[None].copy()
    out = {}
    for target in (eps2, eps3):
        steps = 4000
        stretch = (1.0 + target) / F[0, 0, 0]
        rate = np.log(stretch) / steps  # L dt per step, uniaxial
        for _ in range(steps):
            L = np.zeros((1, 2, 2))
            L[0, 0, 0] = rate
            sigma = law.stress(F, L, sigma, 1.0, np.array([pr.rho0]), state)
            F[0, 0, 0] *= np.exp(rate)
        out[target] = sigma[0, 0, 0]
    assert out[eps2] == pytest.approx(-pr.hel, rel=2e-3)
    assert out[eps3] == pytest.approx(-pr.hel + (lam + 2 * mu / 3) * (eps3 - eps2), rel=3e-3)


def test_too_slow_an_impact_is_refused():
    with pytest.raises(ValueError, match="would not yield"):
        PlasticImpact(v0=0.01)
