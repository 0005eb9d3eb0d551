"""The manufactured body forces against finite differences of the exact motion:
b = d2u/dt2 - Div P / rho0, with F = I + du/dX and P = J sigma(F) F^-T from the problem's own
material law (6th-order central differences, nested), at random points and times."""

import numpy as np
import pytest

from fempm.verification import manufactured as mf

#: 6th-order central first-derivative stencil: offsets and weights
OFFS = np.array([-3.0, -2.0, -1.0, 1.0, 2.0, 3.0])
WTS = np.array([-1.0, 9.0, -45.0, 45.0, -9.0, 1.0]) / 60.0

PROBLEMS = {
    "axis_aligned_1d G=1e-4": mf.axis_aligned_1d(1e-4),
    "axis_aligned_1d G=0.05": mf.axis_aligned_1d(0.05),
    "axis_aligned 2d": mf.axis_aligned(0.05, 2),
    "axis_aligned 3d": mf.axis_aligned(0.05, 3),
    "generalized_vortex A=1": mf.generalized_vortex(1.0),
    "generalized_vortex A=0.01": mf.generalized_vortex(0.01),
    "vibrating_bar": mf.vibrating_bar(),
}


def sample_points(problem, n: int, rng) -> np.ndarray:
    lo, hi = np.array(problem.lower), np.array(problem.upper)
    if problem.name == "generalized_vortex":  # inside the annulus
        r = rng.uniform(problem.r_in, problem.r_out, n)
        a = rng.uniform(0, 2 * np.pi, n)
        return np.column_stack([r * np.cos(a), r * np.sin(a)])
    return lo + (hi - lo) * rng.uniform(0.02, 0.98, (n, problem.dim))


def fd_gradient(f, X: np.ndarray, delta: float) -> np.ndarray:
    """d f / d X (n, k, d) of a vectorised f: (n, d) -> (n, k)."""
    d = X.shape[1]
    cols = []
    for j in range(d):
        e = np.zeros(d)
        e[j] = delta
        cols.append(sum(w * f(X + o * e) for o, w in zip(OFFS, WTS)) / delta)
    return np.stack(cols, axis=-1)


def first_piola(problem, F: np.ndarray) -> np.ndarray:
    n, d, _ = F.shape
    J = np.linalg.det(F)
    rho = problem.rho0 / J
    sigma = problem.material.stress(F, np.zeros_like(F), np.zeros_like(F), 0.0, rho)
    return J[:, None, None] * sigma @ np.linalg.inv(np.swapaxes(F, 1, 2))


def length_scale(problem) -> float:
    """The length over which the motion varies (the annulus width for the vortex)."""
    if problem.name == "generalized_vortex":
        return problem.r_out - problem.r_in
    return max(np.ptp(np.array([problem.lower, problem.upper]), axis=0))


def fd_body_force(problem, X: np.ndarray, t: float) -> np.ndarray:
    d = problem.dim
    L = length_scale(problem)
    dt = 1e-3 * problem.t_end

    def F_of(Y):
        return np.eye(d) + fd_gradient(lambda Z: problem.displacement(Z, t), Y, 1e-4 * L)

    def P_flat(Y):
        return first_piola(problem, F_of(Y)).reshape(len(Y), d * d)

    dP = fd_gradient(P_flat, X, 1e-2 * L).reshape(len(X), d, d, d)  # dP_ij / dX_k
    div_P = np.einsum("nijj->ni", dP)
    acc = sum(w * problem.velocity(X, t + o * dt) for o, w in zip(OFFS, WTS)) / dt
    return acc - div_P / problem.rho0


def fd_velocity(problem, X, t):
    dt = 1e-3 * problem.t_end
    return sum(w * problem.displacement(X, t + o * dt) for o, w in zip(OFFS, WTS)) / dt


@pytest.mark.parametrize("name", sorted(PROBLEMS))
def test_body_force_matches_finite_differences(name):
    """max |b - b_fd| over 40 random points at 4 random times, relative to max |b_fd| there."""
    problem = PROBLEMS[name]
    rng = np.random.default_rng(7)
    X = sample_points(problem, 40, rng)
    times = rng.uniform(0.05, 0.95, 4) * problem.t_end
    b = np.stack([problem.body_force(X, t) for t in times])
    b_fd = np.stack([fd_body_force(problem, X, t) for t in times])
    scale = np.abs(b_fd).max()
    if problem.has_body_force:
        assert scale > 0
        assert np.abs(b - b_fd).max() <= 1e-6 * scale, np.abs(b - b_fd).max() / scale
    else:  # the bar is exact with no body force: the residual is finite-difference noise
        assert np.abs(b).max() == 0.0 and scale <= 1e-6 * problem.v0 * problem.omega


@pytest.mark.parametrize("name", sorted(PROBLEMS))
def test_velocity_and_deformation_are_derivatives_of_the_motion(name):
    problem = PROBLEMS[name]
    rng = np.random.default_rng(3)
    X = sample_points(problem, 30, rng)
    L = length_scale(problem)
    for t in rng.uniform(0.05, 0.95, 3) * problem.t_end:
        v, v_fd = problem.velocity(X, t), fd_velocity(problem, X, t)
        assert np.abs(v - v_fd).max() <= 1e-8 * np.abs(v).max()
        F = problem.deformation_gradient(X, t)
        F_fd = np.eye(problem.dim) + fd_gradient(lambda Z, t=t: problem.displacement(Z, t), X, 1e-4 * L)
        assert np.abs(F - F_fd).max() <= 1e-8


def test_vortex_rims_do_not_move_and_are_traction_free():
    vortex = mf.generalized_vortex(1.0)
    a = np.linspace(0, 2 * np.pi, 9)
    for r in (vortex.r_in, vortex.r_out):
        X = r * np.column_stack([np.cos(a), np.sin(a)])
        assert np.abs(vortex.displacement(X, 0.5)).max() < 1e-14
        F = vortex.deformation_gradient(X, 0.5)
        P = first_piola(vortex, F)
        normal = X / r
        assert np.abs(np.einsum("nij,nj->ni", P, normal)).max() < 1e-10
        assert np.allclose(np.linalg.det(vortex.deformation_gradient(X * 1.1, 0.3)), 1.0)


def test_axis_aligned_walls_hold_the_normal_displacement():
    p = mf.axis_aligned(0.05, 2)
    y = np.linspace(0, 1, 7)
    for a in range(2):
        for v in (0.0, 1.0):
            X = np.column_stack([np.full(7, v), y]) if a == 0 else np.column_stack([y, np.full(7, v)])
            assert np.abs(p.displacement(X, 0.013)[:, a]).max() < 1e-15
    assert p.walls() == [(0, 0.0, "slip"), (0, 1.0, "slip"), (1, 0.0, "slip"), (1, 1.0, "slip")]
