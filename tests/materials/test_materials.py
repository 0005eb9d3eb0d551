"""Materials: frame indifference, small-strain limits, wave speeds, energy-stress consistency."""

import numpy as np
import pytest

from fempm.materials import LinearElastic, NeoHookean, NewtonianTait
from fempm.materials.base import lame


def rotations(n, rng):
    q, _ = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    return q * np.sign(np.linalg.det(q))[:, None, None]


def test_neo_hookean_is_frame_indifferent():
    rng = np.random.default_rng(0)
    F = np.eye(3) + 0.3 * rng.normal(size=(50, 3, 3))
    F = F[np.linalg.det(F) > 0.2]
    Q = rotations(len(F), rng)
    m = NeoHookean(1000.0, 0.3)
    s = m.stress(F, None, None, 0.0, None)
    sQ = m.stress(Q @ F, None, None, 0.0, None)
    np.testing.assert_allclose(sQ, Q @ s @ np.swapaxes(Q, 1, 2), atol=1e-9)
    np.testing.assert_allclose(m.energy_density(Q @ F), m.energy_density(F), atol=1e-9)


@pytest.mark.parametrize("d", [1, 2, 3])
def test_small_strain_limit_matches_linear_elasticity(d):
    rng = np.random.default_rng(1)
    eps = 1e-6 * rng.normal(size=(20, d, d))
    eps = 0.5 * (eps + np.swapaxes(eps, 1, 2))
    F = np.eye(d) + eps
    lin = LinearElastic(200.0, 0.25 if d > 1 else 0.0)
    nh = NeoHookean(200.0, 0.25 if d > 1 else 0.0)
    lam, mu = lame(200.0, lin.nu)
    expected = lam * np.trace(eps, axis1=1, axis2=2)[:, None, None] * np.eye(d) + 2 * mu * eps
    np.testing.assert_allclose(lin.stress(F, None, None, 0, None), expected, atol=1e-12)
    np.testing.assert_allclose(nh.stress(F, None, None, 0, None), expected, rtol=1e-4, atol=1e-9)


def test_neo_hookean_stress_is_the_energy_derivative():
    """Kirchhoff stress tau = J sigma = dW/dF F^T (finite differences of W)."""
    rng = np.random.default_rng(2)
    F = np.eye(2) + 0.2 * rng.normal(size=(5, 2, 2))
    m = NeoHookean(50.0, 0.3)
    h = 1e-6
    P = np.zeros_like(F)
    for i in range(2):
        for j in range(2):
            dF = np.zeros((2, 2))
            dF[i, j] = h
            P[:, i, j] = (m.energy_density(F + dF) - m.energy_density(F - dF)) / (2 * h)
    tau = np.linalg.det(F)[:, None, None] * m.stress(F, None, None, 0, None)
    np.testing.assert_allclose(P @ np.swapaxes(F, 1, 2), tau, rtol=1e-6, atol=1e-6)


def test_wave_speeds_and_tait_pressure():
    lin = LinearElastic(100.0, 0.0)
    np.testing.assert_allclose(lin.wave_speed(np.eye(1)[None], np.array([1.0])), [10.0])
    w = NewtonianTait(rho0=1000.0, kappa=2e4, gamma=7.0, viscosity=0.0)
    rho = np.array([1000.0, 1010.0])
    np.testing.assert_allclose(w.pressure(rho), [0.0, 2e4 * (1.01**7 - 1)])
    s = w.stress(None, np.zeros((2, 2, 2)), None, 0, rho)
    np.testing.assert_allclose(s[1], -2e4 * (1.01**7 - 1) * np.eye(2))
    np.testing.assert_allclose(w.wave_speed(None, rho[:1]), [np.sqrt(2e4 * 7 / 1000)])


def test_invalid_parameters_are_rejected():
    with pytest.raises(ValueError, match="nu"):
        LinearElastic(1.0, 0.5)
    with pytest.raises(ValueError, match="E > 0"):
        NeoHookean(-1.0, 0.3)


def test_a_law_without_what_the_solver_calls_is_named():
    from fempm.materials.base import check_materials

    class NoHistory:
        def stress(self, F, L, sigma, dt, rho):
            return sigma

        def wave_speed(self, F, rho):
            return np.ones(len(F))

        def energy_density(self, F):
            return np.zeros(len(F))

    check_materials([LinearElastic(1.0, 0.3), NeoHookean(1.0)])
    with pytest.raises(TypeError, match=r"material 1 \(NoHistory\) lacks history"):
        check_materials([LinearElastic(1.0, 0.3), NoHistory()])
    with pytest.raises(TypeError, match=r"material 0 \(object\) lacks stress, wave_speed, energy_density, history"):
        check_materials([object()])
