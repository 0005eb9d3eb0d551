"""Return mappings of the plastic laws (fempm.materials.VonMises, DruckerPrager): after any
strain increment the stress lies on or inside the yield surface, elastic increments are exact,
the return is the closest point in the energy norm where the theory says so (J2; associated
Drucker-Prager on the cone), the update is frame indifferent, the plastic dissipation is not
negative; and the internal variables are kept by the solver, serial = 2 ranks."""

import numpy as np
import pytest

from fempm.materials import DruckerPrager, LinearElastic, VonMises
from fempm.materials.hypoelastic import to3

E, NU = 1.0e6, 0.3
LAWS = {
    "von Mises": VonMises(E, NU, yield_stress=1.0e3, hardening=2.0e4),
    "von Mises, perfect": VonMises(E, NU, yield_stress=1.0e3),
    "Drucker-Prager, sand": DruckerPrager(E, NU, friction_angle=30.0),
    "Drucker-Prager, dilatant": DruckerPrager(E, NU, friction_angle=35.0, dilation_angle=10.0, cohesion=500.0),
    "Drucker-Prager, associated": DruckerPrager(E, NU, friction_angle=25.0, dilation_angle=25.0, cohesion=800.0),
}


def _f(law, S, state, d):
    return law.yield_function(S, state["eps_p"]) if isinstance(law, VonMises) else law.yield_function(S, d)


def _scale(law):
    return law.yield_stress if isinstance(law, VonMises) else 1.0e3


def _random_steps(law, d, n=400, steps=12, seed=0, rate=0.2):
    """Random velocity gradients from a compressed state; yields (trial, returned, state, L)."""
    rng = np.random.default_rng(seed)
    sigma = np.zeros((n, d, d))
    sigma[:, range(d), range(d)] = -2.0e3  # confined, so that friction has strength
    state = {"eps_p": np.zeros(n), "sigma_zz": np.full(n, -2.0e3)}
    F = np.broadcast_to(np.eye(d), (n, d, d)).copy()
    for _ in range(steps):
        L = rng.standard_normal((n, d, d)) * rate * rng.random((n, 1, 1))
        before = {k: v.copy() for k, v in state.items()}
        trial = law.trial(L, sigma, 1e-2, before)
        new = law.stress(F, L, sigma, 1e-2, np.ones(n), state)
        yield trial, to3(new, state.get("sigma_zz")), state, before
        sigma = new


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("name", list(LAWS))
def test_stress_on_or_inside_the_yield_surface(name, d):
    law = LAWS[name]
    plastic = 0
    for trial, S, state, _ in _random_steps(law, d):
        f = _f(law, S, state, d)
        assert f.max() <= 1e-10 * _scale(law), name
        returned = np.abs(S - trial).max(axis=(1, 2)) > 1e-9 * _scale(law)
        plastic += np.count_nonzero(returned)
        assert np.abs(f[returned & (f < -1e-8 * _scale(law))]).size == 0 or isinstance(law, DruckerPrager)
    assert plastic > 100  # the increments do reach the surface


@pytest.mark.parametrize("name", list(LAWS))
def test_elastic_increments_are_exact(name):
    """A small increment from a state inside the surface: the hypoelastic update, which for
    zero spin and zero initial stress is the linear elastic one."""
    law = LAWS[name]
    n, d = 50, 2
    rng = np.random.default_rng(3)
    L = 1e-6 * sym_(rng.standard_normal((n, d, d)))
    state = {"eps_p": np.zeros(n), "sigma_zz": np.zeros(n)}
    sigma = np.zeros((n, d, d)) if isinstance(law, VonMises) else np.broadcast_to(-1e3 * np.eye(d), (n, d, d)).copy()
    if isinstance(law, DruckerPrager):
        state["sigma_zz"][:] = -1e3
    dt = 1.0
    new = law.stress(None, L, sigma, dt, np.ones(n), state)
    elastic = LinearElastic(E, NU).stress_numpy(np.eye(d) + L * dt, None, None, dt, None)
    assert np.abs(new - sigma - elastic).max() < 1e-9 * np.abs(elastic).max()
    lam = LinearElastic(E, NU).lame[0]
    assert np.allclose(state["sigma_zz"] - (0 if isinstance(law, VonMises) else -1e3),
                       lam * np.trace(L, axis1=1, axis2=2) * dt, rtol=1e-9, atol=0)
    assert np.all(state["eps_p"] == 0)


def sym_(A):
    return 0.5 * (A + np.swapaxes(A, 1, 2))


def _energy_gradient(law, trial, S):
    """C^-1 (trial - S): the plastic strain increment of the return."""
    lam, mu = law.lame
    K = lam + 2 * mu / 3
    dS = trial - S
    p = np.trace(dS, axis1=1, axis2=2) / 3
    return (dS - p[:, None, None] * np.eye(3)) / (2 * mu) + (p / (3 * K))[:, None, None] * np.eye(3)


@pytest.mark.parametrize("name", ["von Mises", "von Mises, perfect", "Drucker-Prager, associated"])
def test_the_return_is_the_closest_point_in_the_energy_norm(name):
    """Associated flow: the plastic strain increment C^-1 (trial - S) is normal to the yield
    surface at the returned stress (away from the apex), the optimality condition of the
    closest-point projection in the energy norm; von Mises keeps the pressure."""
    law = LAWS[name]
    checked = 0
    for trial, S, _state, _ in _random_steps(law, 3, seed=5):
        p = np.trace(S, axis1=1, axis2=2) / 3
        dev = S - p[:, None, None] * np.eye(3)
        root = np.sqrt(0.5 * np.einsum("nij,nij->n", dev, dev))
        plastic = (np.abs(S - trial).max(axis=(1, 2)) > 1e-9 * _scale(law)) & (root > 1e-6 * _scale(law))
        eta = 0.0 if isinstance(law, VonMises) else law.parameters(3)[0]
        normal = dev[plastic] / (2 * root[plastic, None, None]) + eta / 3 * np.eye(3)
        deps = _energy_gradient(law, trial[plastic], S[plastic])
        cos = np.einsum("nij,nij->n", deps, normal) / (np.linalg.norm(deps, axis=(1, 2)) *
                                                         np.linalg.norm(normal, axis=(1, 2)))
        assert np.all(cos > 1 - 1e-10)
        if isinstance(law, VonMises):
            assert np.allclose(np.trace(trial[plastic], axis1=1, axis2=2), 3 * p[plastic], rtol=1e-12, atol=1e-9)
        checked += np.count_nonzero(plastic)
    assert checked > 100


@pytest.mark.parametrize("name", list(LAWS))
def test_frame_indifference(name):
    """A superposed constant rotation Q of the stress, the state and L rotates the update."""
    law = LAWS[name]
    n, d = 200, 3
    rng = np.random.default_rng(11)
    Q, _ = np.linalg.qr(rng.standard_normal((d, d)))
    sigma = sym_(rng.standard_normal((n, d, d))) * 500.0 - 2e3 * np.eye(d)
    L = rng.standard_normal((n, d, d)) * 0.3
    a = {"eps_p": np.zeros(n)}
    b = {"eps_p": np.zeros(n)}
    new = law.stress(None, L, sigma, 1e-2, np.ones(n), a)
    rotated = law.stress(None, Q @ L @ Q.T, Q @ sigma @ Q.T, 1e-2, np.ones(n), b)
    assert np.abs(rotated - Q @ new @ Q.T).max() < 1e-11 * np.abs(new).max()
    assert np.allclose(a["eps_p"], b["eps_p"], rtol=1e-11, atol=1e-18) and a["eps_p"].max() > 0


@pytest.mark.parametrize("name", list(LAWS))
def test_plastic_dissipation_is_not_negative(name):
    """sigma : (C^-1 (trial - sigma)) >= 0 at every return (non-associated flow included)."""
    law = LAWS[name]
    for trial, S, _, _ in _random_steps(law, 2, seed=7):
        dissipation = np.einsum("nij,nij->n", S, _energy_gradient(law, trial, S))
        assert dissipation.min() >= -1e-9 * np.abs(S).max() ** 2 / E


def test_bad_parameters():
    with pytest.raises(ValueError, match="yield_stress > 0"):
        VonMises(E, NU, yield_stress=0.0)
    with pytest.raises(ValueError, match="dilation_angle <= friction_angle"):
        DruckerPrager(E, NU, friction_angle=20.0, dilation_angle=30.0)
    with pytest.raises(ValueError, match="cohesion >= 0"):
        DruckerPrager(E, NU, cohesion=-1.0)
    with pytest.raises(ValueError, match="2D .plane strain. or 3D"):
        VonMises(E, NU, 1.0).stress(None, np.zeros((1, 1, 1)), np.zeros((1, 1, 1)), 1.0, np.ones(1),
                                    {"eps_p": np.zeros(1)})


def _biaxial(phi: float, psi: float, steps: int = 1500, rate: float = 2e-4, p0: float = 1e4):
    """Drained plane-strain biaxial compression of one point of DruckerPrager(phi, psi): the
    axial rate -rate, the lateral rate found each step (secant) to keep sigma_xx = -p0; returns
    the final stress and the lateral over the axial strain rate."""
    law = DruckerPrager(1e7, 0.3, friction_angle=phi, dilation_angle=psi)
    sigma = -p0 * np.eye(2)[None].copy()
    state = {"eps_p": np.zeros(1), "sigma_zz": np.array([-p0])}

    def update(exx):
        copied = {k: v.copy() for k, v in state.items()}
        return law.stress(None, np.array([[[exx, 0.0], [0.0, -rate]]]), sigma, 1.0, np.ones(1), copied), copied

    exx = 0.0
    for _ in range(steps):
        a, b = 0.0, rate
        fa, fb = update(a)[0][0, 0, 0] + p0, update(b)[0][0, 0, 0] + p0
        for _ in range(30):
            a, fa, b = b, fb, b - fb * (b - a) / (fb - fa)
            fb = update(b)[0][0, 0, 0] + p0
            if abs(fb) < 1e-10 * p0:
                break
        sigma, state = update(b)
        exx = b
    return sigma[0], exx / rate


@pytest.mark.parametrize("phi, psi", [(30.0, 0.0), (30.0, 10.0), (30.0, 30.0), (40.0, 0.0), (40.0, 20.0)])
def test_drucker_prager_matches_mohr_coulomb_in_steady_plane_strain_flow(phi, psi):
    """Steady plane-strain flow (drained biaxial compression, sigma_zz tracked): the mobilised
    friction angle asin((s1 - s2) / -(s1 + s2)) is the friction angle and the dilatancy
    (e1 + e2)/(e1 - e2) that of the dilation angle, for non-associated flow too. Before, the
    associated match gave 28.7 degrees for 30 and 37.1 for 40 with dilation_angle = 0."""
    s, lateral = _biaxial(phi, psi)
    mobilised = np.degrees(np.arcsin((s[0, 0] - s[1, 1]) / -(s[0, 0] + s[1, 1])))
    assert mobilised == pytest.approx(phi, abs=1e-9)
    assert lateral == pytest.approx((1 + np.sin(np.radians(psi))) / (1 - np.sin(np.radians(psi))), rel=1e-9)
