"""The laws' tangents dsigma/dG of an increment against central differences of the stress
update they differentiate (fempm.materials.tangent), in every regime of the return mappings, and
the nominal stress's tangent (fempm.implicit.nominal)."""

import numpy as np
import pytest

import fempm  # noqa: F401  (before dolfinx)
from fempm.implicit import nominal_stress
from fempm.materials import DruckerPrager, LinearElastic, NeoHookean, VonMises
from fempm.materials.tangent import finite_difference_tangent, stress_after, tangent_of

TOL = 1e-6  # relative to the largest entry of the particle's tangent


def relative_errors(D, Dfd):
    n = len(D)
    scale = np.abs(Dfd).reshape(n, -1).max(axis=1)
    return np.abs(D - Dfd).reshape(n, -1).max(axis=1) / np.where(scale > 0, scale, 1.0)


def symmetric(rng, n, d, scale, shift=0.0):
    S = scale * rng.standard_normal((n, d, d))
    return 0.5 * (S + np.swapaxes(S, 1, 2)) + shift * np.eye(d)


def plastic_state(n, zz=None):
    return {"eps_p": np.full(n, 0.01), "sigma_zz": np.zeros(n) if zz is None else zz}


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("law", [LinearElastic(1e3, 0.3), NeoHookean(1e3, 0.3), NeoHookean(5.0, 0.45)],
                         ids=["linear", "neo-hookean", "neo-hookean-stiff-bulk"])
def test_elastic_tangents_at_finite_strain(law, d):
    rng = np.random.default_rng(10 + d)
    n = 8
    F = np.eye(d) + 0.2 * rng.standard_normal((n, d, d))  # finite strain at the step's start
    F[np.linalg.det(F) < 0.2] = np.eye(d)
    G = 0.1 * rng.standard_normal((n, d, d))
    sigma, rho = np.zeros((n, d, d)), np.ones(n)
    D = tangent_of(law, F, G, sigma, rho)
    assert np.all(relative_errors(D, finite_difference_tangent(law, F, G, sigma, rho)) < TOL)


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("hardening", [0.0, 800.0])
def test_von_mises_algorithmic_tangent(d, hardening):
    rng = np.random.default_rng(20 + d)
    n = 8
    law = VonMises(1e4, 0.3, yield_stress=10.0, hardening=hardening)
    F, rho = np.eye(d) + 0.02 * rng.standard_normal((n, d, d)), np.ones(n)
    sigma = symmetric(rng, n, d, 1.0, shift=-4.0)  # inside the yield surface (q of about 3 against 10)
    state = plastic_state(n, zz=-4.0 + rng.standard_normal(n))
    small = 1e-5 * rng.standard_normal((n, d, d))  # elastic: the trial stays inside
    large = 5e-3 * rng.standard_normal((n, d, d))  # plastic: trial stresses of about 50 against 10
    for G, plastic in ((small, False), (large, True)):
        _, new = stress_after(law, F, G, sigma, rho, state)
        assert np.all((new["eps_p"] > state["eps_p"]) == plastic)
        D = tangent_of(law, F, G, sigma, rho, state)
        assert np.all(relative_errors(D, finite_difference_tangent(law, F, G, sigma, rho, state)) < TOL)
        assert np.array_equal(state["eps_p"], np.full(n, 0.01))  # the step's state is left as it was


def dp_regime(law, S, d):
    """'elastic', 'cone', 'apex' or 'cut-off' of trial stresses S (n, 3, 3) (the reference's
    arithmetic)."""
    lam, G = law.lame
    K = lam + 2 * G / 3
    eta, k, eta_bar, p_t = law.parameters(d)
    p = np.trace(S, axis1=1, axis2=2) / 3
    dev = S - p[:, None, None] * np.eye(3)
    root = np.sqrt(0.5 * np.einsum("nij,nij->n", dev, dev))
    f = root + eta * p - k
    dgamma = np.maximum(f, 0.0) / (G + K * eta * eta_bar)
    out = np.where(f > 0, np.where(root - G * dgamma < 0, "apex", "cone"), "elastic").astype(object)
    p_new = np.where(out == "cone", p - K * eta_bar * dgamma, p)
    out[(out != "apex") & (p_new > p_t)] = "cut-off"
    return out


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("regime", ["elastic", "cone", "apex", "cut-off"])
@pytest.mark.parametrize("angles", [(30.0, 0.0), (30.0, 30.0), (40.0, 10.0), (0.0, 0.0)],
                         ids=["psi0", "associated", "phi40-psi10", "tresca-like"])
def test_drucker_prager_algorithmic_tangent(d, regime, angles):
    rng = np.random.default_rng(30 + d)
    n = 8
    phi, psi = angles
    cohesion = 5.0 if phi == 0.0 or regime == "cut-off" else 1.0
    law = DruckerPrager(1e4, 0.3, friction_angle=phi, dilation_angle=psi, cohesion=cohesion,
                        tension=0.5 if regime == "cut-off" else None)
    F, rho = np.eye(d) + 0.02 * rng.standard_normal((n, d, d)), np.ones(n)
    if regime == "apex" and phi == 0.0:
        pytest.skip("a cone of no friction (eta = 0) has no apex")
    shear = {"elastic": 1e-6, "cone": 5e-3, "apex": 1e-6, "cut-off": 1e-6}[regime]
    volume = {"elastic": -1e-5, "cone": -1e-4, "apex": 2e-3, "cut-off": 2e-4}[regime]
    sigma = symmetric(rng, n, d, 0.2 if regime != "cone" else 1.0, shift=-3.0 if regime != "cut-off" else 0.0)
    state = plastic_state(n, zz=np.full(n, -3.0 if regime != "cut-off" else 0.0))
    G = shear * rng.standard_normal((n, d, d))
    G += (volume - np.trace(G, axis1=1, axis2=2) / d)[:, None, None] * np.eye(d)  # volumetric strain: volume
    trial = law.trial(G, sigma, 1.0, state)
    assert np.all(dp_regime(law, trial, d) == regime)
    D = tangent_of(law, F, G, sigma, rho, state)
    Dfd = finite_difference_tangent(law, F, G, sigma, rho, state)
    assert np.all(relative_errors(D, Dfd) < TOL)
    if regime == "apex":
        assert np.abs(D).max() == 0.0 and np.abs(Dfd).max() < 1e-6  # the apex point does not move


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("law", [NeoHookean(1e3, 0.3), VonMises(1e4, 0.3, yield_stress=10.0, hardening=100.0)],
                         ids=["neo-hookean", "von-mises-plastic"])
def test_nominal_stress_and_its_tangent(law, d):
    rng = np.random.default_rng(40 + d)
    n = 6
    F, rho = np.eye(d) + 0.1 * rng.standard_normal((n, d, d)), np.ones(n)
    G = 0.05 * rng.standard_normal((n, d, d))
    sigma = np.zeros((n, d, d))
    state = plastic_state(n) if law.history else None

    def nominal_of(G):
        s = stress_after(law, F, G, sigma, rho, state)[0]
        dF = np.eye(d) + G
        return np.linalg.det(dF)[:, None, None] * s @ np.linalg.inv(dF).transpose(0, 2, 1)

    s = stress_after(law, F, G, sigma, rho, state)[0]
    P, A = nominal_stress(s, tangent_of(law, F, G, sigma, rho, state), G)
    np.testing.assert_allclose(P, nominal_of(G), rtol=0, atol=1e-12 * np.abs(P).max())
    Afd = np.empty_like(A)
    h = 1e-6
    for k in range(d):
        for m in range(d):
            E = np.zeros((d, d))
            E[k, m] = h
            Afd[..., k, m] = (nominal_of(G + E) - nominal_of(G - E)) / (2 * h)
    assert np.all(relative_errors(A, Afd) < TOL)


def test_an_inverting_increment_is_refused():
    G = np.array([[[-2.0, 0.0], [0.0, 0.0]]])
    with pytest.raises(ValueError, match=r"inverts 1 particle\(s\): det\(I \+ G\) <= 0"):
        nominal_stress(np.zeros((1, 2, 2)), np.zeros((1, 2, 2, 2, 2)), G)


class NoTangent:
    """A user law with a stress and no tangent (small-strain, linear)."""

    history = ()

    def stress(self, F, L, sigma, dt, rho):
        eps = 0.5 * (F + np.swapaxes(F, 1, 2)) - np.eye(F.shape[1])
        return 100.0 * eps + 50.0 * np.trace(eps, axis1=1, axis2=2)[:, None, None] * np.eye(F.shape[1])


class WrongShape(NoTangent):
    def tangent(self, F, G, sigma, state):
        return np.zeros((len(F), 2, 2))


def test_a_law_without_tangent_asks_for_the_finite_difference_one_by_name():
    F, G, sigma, rho = np.tile(np.eye(2), (3, 1, 1)), np.zeros((3, 2, 2)), np.zeros((3, 2, 2)), np.ones(3)
    with pytest.raises(TypeError, match=r"NoTangent has no tangent.*finite_difference=True"):
        tangent_of(NoTangent(), F, G, sigma, rho)
    D = tangent_of(NoTangent(), F, G, sigma, rho, finite_difference=True)
    expected = LinearElastic(1.0, 0.0).tangent(F, G)  # lambda = 0, mu = 1/2; the law has lambda = mu = 50
    expected = 100.0 * expected + 50.0 * np.einsum("ij,nlk->nijkl", np.eye(2), F)
    np.testing.assert_allclose(D, expected, rtol=0, atol=1e-7)
    with pytest.raises(ValueError, match=r"WrongShape.tangent returned an array of shape \(3, 2, 2\)"):
        tangent_of(WrongShape(), F, G, sigma, rho)
