"""The mu(I) rheology (fempm.materials.MuI): the compiled return against its numpy definition,
steady pure shear at the friction mu(I) of its inertial number (from the static mu_s to near
mu_2), elastic below mu_s P, no stress in tension, bad parameters, and the implicit step's
refusal."""

import numpy as np
import pytest

import fempm  # noqa: F401  (before dolfinx)
from fempm.kernels.granular import mu_i_return_numba, mu_i_return_numpy
from fempm.materials import MuI
from fempm.materials.base import identity

LAW = MuI(1e6, 0.3)


def _trial_stresses(n, rng):
    S = rng.standard_normal((n, 3, 3)) * 1e3
    S = 0.5 * (S + S.transpose(0, 2, 1))
    S[:, range(3), range(3)] -= rng.uniform(-500.0, 3000.0, (n, 1))  # some in tension
    return S


def test_the_compiled_return_is_the_numpy_one():
    rng = np.random.default_rng(0)
    S = _trial_stresses(400, rng)
    eps = rng.uniform(0, 1e-2, 400)
    args = (1e-4, LAW.mu_s, LAW.mu_2, LAW.I_0, LAW.grain_diameter, LAW.grain_density, LAW.lame[1])
    a, ea = mu_i_return_numba(S, eps, *args)
    b, eb = mu_i_return_numpy(S, eps, *args)
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(ea, eb, rtol=1e-12, atol=1e-18)
    p = np.trace(a, axis1=1, axis2=2) / 3
    kinds = {"tension": (p == 0).sum(), "flowing": (ea > eps).sum(), "elastic": (ea == eps).sum()}
    assert min(kinds.values()) > 20, kinds  # every branch is exercised


def _pure_shear(law, rate, pressure, steps=4000):
    """A plane-strain particle under pressure sheared at D = diag(rate, -rate): (tau / P, I)."""
    dt = 20.0 / rate / steps  # a total strain of 20
    L = np.array([[[rate, 0.0], [0.0, -rate]]])
    sigma = -pressure * identity(1, 2)
    state = {"eps_p": np.zeros(1), "sigma_zz": np.full(1, -pressure)}
    for _ in range(steps):
        sigma = law.stress(identity(1, 2), L, sigma, dt, np.ones(1), state)
    S = np.zeros((3, 3))
    S[:2, :2], S[2, 2] = sigma[0], state["sigma_zz"][0]
    P = -np.trace(S) / 3
    dev = S + P * np.eye(3)
    return np.sqrt(0.5 * np.sum(dev * dev)) / P, P


@pytest.mark.parametrize("rate", [1e-3, 1.0, 30.0, 300.0, 3000.0])
def test_steady_pure_shear_runs_at_the_friction_of_its_inertial_number(rate):
    """The plastic shear rate of D = diag(e, -e) is 2 e (gamma = sqrt(2) |D'|); the flow is
    isochoric, the pressure stays; tau / P is mu(I) to 1e-9 once the elastic transient is past."""
    ratio, P = _pure_shear(LAW, rate, 1e3)
    assert P == pytest.approx(1e3, rel=1e-12)
    I = LAW.inertial_number(2 * rate, P)
    assert ratio == pytest.approx(LAW.friction(I), rel=1e-9), (I, ratio)
    if rate <= 1e-3:
        assert ratio == pytest.approx(LAW.mu_s, rel=1e-5)  # the static limit
    if rate >= 3000.0:
        assert ratio > LAW.mu_s + 0.8 * (LAW.mu_2 - LAW.mu_s)  # approaches mu_2


def test_below_the_static_friction_the_stress_is_elastic_and_tension_frees_the_grains():
    S = np.zeros((3, 3, 3))
    S[:] = -1e3 * np.eye(3)
    S[0, 0, 1] = S[0, 1, 0] = 0.9 * LAW.mu_s * 1e3  # sqrt(J2) = that shear: below mu_s P
    S[1] += 2e3 * np.eye(3)  # mean stress +1e3: tension
    S[1, 0, 1] = S[1, 1, 0] = 100.0
    S[2, 0, 1] = S[2, 1, 0] = 2.0 * LAW.mu_s * 1e3  # flows
    out, eps = LAW.return_map(S, np.zeros(3), 1e-4)
    np.testing.assert_array_equal(out[0], S[0])
    np.testing.assert_array_equal(out[1], 0.0)
    assert eps[0] == 0.0 and eps[1] > 0.0 and eps[2] > 0.0
    assert np.trace(out[2]) == pytest.approx(-3e3)  # the pressure kept
    assert LAW.mu_s < abs(out[2, 0, 1]) / 1e3 < LAW.mu_2


@pytest.mark.parametrize("kwargs, message", [
    ({"mu_s": 0.0}, "0 < mu_s"), ({"mu_s": 0.5, "mu_2": 0.4}, "mu_s <= mu_2"), ({"I_0": -1.0}, "I_0 > 0"),
    ({"grain_diameter": 0.0}, "grain_diameter > 0"), ({"grain_density": float("nan")}, "grain_density"),
])
def test_bad_parameters_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        MuI(1e6, 0.3, **kwargs)


def test_the_implicit_step_refuses_a_rate_dependent_law():
    from fempm.scenes.cook import cook_membrane
    from fempm.stepping import StepOptions

    scene = cook_membrane(h=8.0)
    scene.materials = [LAW]
    scene.options = StepOptions(integrator="implicit", dynamics="newmark")
    with pytest.raises(ValueError, match="MuI is rate-dependent"):
        scene.solver()
