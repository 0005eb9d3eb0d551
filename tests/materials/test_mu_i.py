"""The mu(I) rheology (fempm.materials.MuI): the compiled return against its numpy definition,
steady pure shear at the friction mu(I) of its inertial number (from the static mu_s to near
mu_2), elastic below mu_s P, no stress in tension, bad parameters, the algorithmic tangent, and
an implicit collapse converging in dt to the explicit one."""

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


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("size, dt", [(1e-6, 1e-3), (3e-3, 1e-3), (3e-3, 1e-5), (3e-3, 1e-2)],
                         ids=["elastic", "flowing", "fast", "slow"])
def test_the_algorithmic_tangent_is_the_derivative_of_the_return(d, size, dt):
    """dsigma/dG over a step dt against central differences of the stress update with that dt,
    in the elastic, flowing and separated (zero-stress) regimes."""
    from fempm.materials.tangent import finite_difference_tangent, stress_after, tangent_of

    rng = np.random.default_rng(int(1e6 * size) + d)
    n = 12
    F, rho = np.eye(d) + 0.01 * rng.standard_normal((n, d, d)), np.full(n, 1500.0)
    sigma = 100.0 * rng.standard_normal((n, d, d))
    sigma = 0.5 * (sigma + np.swapaxes(sigma, 1, 2)) - 1000.0 * np.eye(d)
    sigma[:2] = 1e5 * np.eye(d)  # in tension: the grains separate
    state = {"eps_p": np.zeros(n), "sigma_zz": np.full(n, -1000.0)}
    state["sigma_zz"][:2] = 1e5
    G = size * rng.standard_normal((n, d, d))
    flows = stress_after(LAW, F, G, sigma, rho, state, dt)[1]["eps_p"][2:] > 0
    assert flows.sum() >= 5 if size > 1e-4 else not flows.any()  # some elastic, some flowing
    D = tangent_of(LAW, F, G, sigma, rho, state, dt=dt)
    Dfd = finite_difference_tangent(LAW, F, G, sigma, rho, state, step=1e-7, dt=dt)
    assert np.all(D[:2] == 0.0) and np.all(Dfd[:2] == 0.0)
    scale = np.abs(Dfd[2:]).reshape(n - 2, -1).max(axis=1)
    assert np.all(np.abs(D - Dfd)[2:].reshape(n - 2, -1).max(axis=1) <= 1e-7 * scale)


def collapse(**options):
    """A mu(I) block 0.1 m square on a slip floor against a slip wall, released from K0 = 0.6
    geostatic stresses (quadrilaterals of 1/80 m, 4 particles per cell)."""
    import dolfinx.fem
    import dolfinx.mesh
    from mpi4py import MPI

    from fempm.boundary import slip
    from fempm.stepping import ExplicitSolver, Loads, StepOptions

    mesh = dolfinx.mesh.create_rectangle(MPI.COMM_WORLD, [[0.0, 0.0], [0.3, 0.15]], [24, 12],
                                         dolfinx.mesh.CellType.quadrilateral)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    p = fempm.create_particles(mesh, 4, density=1500.0, cells=lambda x: (x[0] < 0.1) & (x[1] < 0.1))
    syy = -1500.0 * 9.81 * (0.1 - p.x[:, 1])
    p.fields["sigma"] = np.zeros((len(p), 2, 2))
    p.fields["sigma"][:, 0, 0], p.fields["sigma"][:, 1, 1] = 0.6 * syy, syy
    p.fields["sigma_zz"] = 0.6 * syy
    bcs = [slip(V, lambda x: np.isclose(x[0], 0.0), (-1.0, 0.0)), slip(V, lambda x: np.isclose(x[1], 0.0), (0.0, -1.0))]
    return ExplicitSolver(V, p, [MuI(2e6, 0.3)], bcs=bcs, loads=Loads(body_force=(0.0, -9.81)),
                          options=StepOptions(flip=0.99, **options))


def front(solver):
    from mpi4py import MPI

    return solver.particles.comm.allreduce(float(solver.particles.x[:, 0].max()), op=MPI.MAX)


def test_an_implicit_mu_i_collapse_converges_in_dt_to_the_explicit_run():
    """Newmark steps of 4, 2 and 1 ms to t = 40 ms with the algorithmic tangent: Newton
    converges quadratically, the finite-difference tangent gives the same motion, and the
    block's front converges at first order in dt (the return is backward Euler in the rate) to
    the explicit run's (measured 0.10275 m explicit, implicit 0.10204 / 0.10235 / 0.10251:
    differences 3.1e-4, 1.6e-4, order 0.91, Richardson's limit 0.10270)."""
    T, implicit = 0.04, {"integrator": "implicit", "dynamics": "newmark"}
    e = collapse(scheme="MUSL")
    while e.t < T - 1e-12:
        e.step(min(e.stable_dt(), T - e.t))
    fronts = []
    for dt in (4e-3, 2e-3, 1e-3):
        s = collapse(**implicit)
        for _ in range(round(T / dt)):
            s.step(dt)
            r = s.implicit.last.residuals / s.implicit.last.residuals[0]
            q = [np.log(r[k + 1]) / np.log(r[k]) for k in range(len(r) - 1) if r[k] < 1e-3 and r[k + 1] > 1e-12]
            assert s.implicit.last.converged and min(q, default=2.0) > 1.6, r  # quadratic where asymptotic
        fronts.append(front(s))
    steps = np.abs(np.diff(fronts))
    order = np.polyfit(np.log([4e-3, 2e-3]), np.log(steps), 1)[0]
    limit = fronts[-1] + steps[-1] / (2.0**order - 1.0)
    print("explicit", front(e), "implicit", fronts, "order", order, "limit", limit)
    assert 0.7 < order < 1.3
    errors = np.abs(np.array(fronts) - front(e))
    assert np.all(np.diff(errors) < 0) and abs(limit - front(e)) < 0.3 * errors[-1]
    fd = collapse(**implicit, tangent="finite-difference")
    for _ in range(5):
        fd.step(2e-3)
    analytic = collapse(**implicit)
    for _ in range(5):
        analytic.step(2e-3)
    assert np.abs(fd.particles.x - analytic.particles.x).max() < 1e-10
