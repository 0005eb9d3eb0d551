"""The implicit step (fempm.implicit): Newton's quadratic convergence, Cook's membrane against the
finite element reference, Newmark's method on the vibrating bar, step cuts, and its errors; on 1
and 2 ranks (the 2-rank run against the same problem on one rank)."""

import numpy as np
import pytest
from mpi4py import MPI

import fempm  # before dolfinx
from fempm.materials import NeoHookean, VonMises
from fempm.scenes.bar import vibrating_bar
from fempm.scenes.cook import cook_membrane, corner_displacement, displacement_reference
from fempm.stepping import ExplicitSolver, Loads, SimulationError, StepOptions


#: the vertical displacement of C per unit load, Taylor-Hood P2-P4 extrapolated, nu = 1/3
#: (docs/verification.md, fempm.studies.scenes.COOK_FE)
COOK_REFERENCE = 22.611
QUASI_STATIC = {"integrator": "implicit", "dynamics": "quasi-static"}


def cook_solver(h, comm=MPI.COMM_WORLD, **options):
    scene = cook_membrane(h=h, nu=1 / 3, load=1e-3, comm=comm)
    scene.options = StepOptions(**{**QUASI_STATIC, **options})
    return scene.solver()


@pytest.mark.parametrize("law, load", [(None, 1e-3), (NeoHookean(1.0, 1 / 3), 0.02)],
                         ids=["linear-elastic", "neo-hookean-finite-strain"])
def test_newton_converges_quadratically_on_cooks_membrane(law, load):
    scene = cook_membrane(h=4.0, nu=1 / 3, load=load)
    scene.options = StepOptions(**QUASI_STATIC)
    if law is not None:
        scene.materials = [law]
    s = scene.solver()
    s.step(1.0)
    r = s.implicit.last.residuals
    print("SNES residual norms:", " ".join(f"{v:.3e}" for v in r))
    assert s.implicit.last.converged and 2 <= s.implicit.last.iterations <= 5
    e = r / r[0]
    # the order q of e_(k+1) = e_k^q, where Newton is in its asymptotic range (e_k < 1e-2) and
    # above the round-off floor (about 2e-11)
    orders = [np.log(e[k + 1]) / np.log(e[k]) for k in range(len(e) - 1) if e[k] < 1e-2 and e[k + 1] > 1e-10]
    assert orders and min(orders) >= 1.8, orders


def test_a_near_incompressible_membrane_converges_and_locks():
    """nu = 0.4999: Newton stops at the round-off floor (2e-8 of the first residual) on its step
    norm; P1 locks as the P1 finite element solution on the same mesh does (-38 % at h = 4):
    the particles seeded per triangle integrate its stiffness exactly."""
    scene = cook_membrane(h=4.0, nu=0.4999, load=1e-3)
    scene.options = StepOptions(**QUASI_STATIC)
    s = scene.solver()
    s.step(1.0)
    assert s.implicit.last.converged and s.implicit.last.iterations <= 4
    uy = corner_displacement(s.particles)[1] / 1e-3
    assert uy == pytest.approx(displacement_reference(0.4999, h=4.0)[1], rel=1e-4)


def test_load_steps_after_the_first_stop_at_the_residuals_round_off_floor():
    """The second step of the same membrane starts from a loaded body: its residual stalls at
    7e-12 against a force tolerance of 4e-13 (every step used to be halved six times and the run
    stopped); the solve that reached the floor (ImplicitStep._round_off) has converged."""
    scene = cook_membrane(h=4.0, nu=0.4999, load=1e-3)
    scene.options = StepOptions(**QUASI_STATIC)
    s = scene.solver()
    for _ in range(3):
        s.step(1.0)
    assert s.record.cut_steps == 0 and s.implicit.last.converged
    assert s.implicit.last.reason in ("CONVERGED_ROUND_OFF", "CONVERGED_SNORM_RELATIVE", "CONVERGED_FNORM_ABS")
    uy = corner_displacement(s.particles)[1] / 1e-3
    # the same locked answer: the load acts from the first step
    assert uy == pytest.approx(displacement_reference(0.4999, h=4.0)[1], rel=1e-4)


def test_a_plastic_membrane_converges_in_load_steps():
    """Cook's membrane with J2 plasticity yielding from the fourth of five load steps: each step
    converges (the algorithmic tangent: quadratic once the plastic zone settles), no cut."""
    scene = cook_membrane(h=4.0, nu=1 / 3, load=1e-3)
    scene.materials = [VonMises(1.0, 1 / 3, yield_stress=2e-4, hardening=0.05)]
    scene.options = StepOptions(**QUASI_STATIC, load_ramp=1.0)
    s = scene.solver()
    for _ in range(5):
        s.step(0.2)
        e = s.implicit.last.residuals / s.implicit.last.residuals[0]
        # the last iterations quadratic, down to round-off (a last residual of 5.6e-14 after 6.0e-8)
        assert e[-1] < 1e-8 and e[-2] < 1e-2 and e[-1] < max(10 * e[-2] ** 2, 1e-12), e
    eps_p = s.particles.comm.allreduce(float(s.particles.fields["eps_p"].max(initial=0.0)), op=MPI.MAX)
    assert eps_p > 5e-5 and s.record.cut_steps == 0  # measured 7.7e-5


@pytest.mark.parametrize("steps", [1, 4])
@pytest.mark.parallel(only=("1",))
def test_cook_quasi_static_is_the_p1_answer_and_converges(steps):
    """The scene's defaults (4 particles per triangle, the consistent load) give the P1 finite
    element answer on the same mesh (measured within 1.8e-4 / 2.8e-4 in 1 / 4 steps at h = 4:
    the particles move with the load, a finite-strain step; 2.3e-5 at a tenth of the load) and
    converge as it does: -5.00 / -2.06 % at h = 4 / 2
    (order 1.28; -0.94 / -0.45 % at h = 1 / 0.5, docs/convergence.md)."""
    errors = []
    for h in (4.0, 2.0):
        s = cook_solver(h, load_ramp=1.0)
        for _ in range(steps):
            s.step(1.0 / steps)
        assert s.t == pytest.approx(1.0) and s.record.cut_steps == 0
        uy = corner_displacement(s.particles)[1] / 1e-3
        assert uy == pytest.approx(displacement_reference(1 / 3, h=h)[1], rel=5e-4)
        errors.append(abs(uy / COOK_REFERENCE - 1.0))
    order = np.polyfit(np.log([4.0, 2.0]), np.log(errors), 1)[0]
    assert errors[1] < 0.025 and order > 1.0, (errors, order)


@pytest.mark.parallel
def test_two_ranks_equal_one_rank():
    world = cook_solver(4.0)
    world.step(1.0)
    alone = cook_solver(4.0, comm=MPI.COMM_SELF)
    alone.step(1.0)
    u_world, u_alone = corner_displacement(world.particles), corner_displacement(alone.particles)
    np.testing.assert_allclose(u_world, u_alone, rtol=1e-9)
    assert world.implicit.last.iterations == alone.implicit.last.iterations


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
@pytest.mark.parallel(only=("consistent",))
def test_newmark_on_the_vibrating_bar_at_courant_4(mass):
    scene = vibrating_bar(cells=16)
    pr = scene.params
    scene.options = StepOptions(integrator="implicit", dynamics="newmark", mass=mass)
    s = scene.solver()
    c = np.sqrt(pr["E"] / pr["rho"])
    dt = 4.0 * (pr["L"] / pr["cells"]) / c  # Courant number 4: ten explicit steps at CFL 0.4
    period = 2 * np.pi / pr["omega"]
    e0 = s.energies()["total"]
    p = s.particles
    amplitude = pr["v0"] / (pr["beta"] * pr["L"])
    worst = 0.0
    for _ in range(round(period / dt)):
        s.step(dt)
        v_cm = p.comm.allreduce(float(np.sum(p.mass * p.fields["v"][:, 0]))) / p.comm.allreduce(float(np.sum(p.mass)))
        worst = max(worst, abs(v_cm - amplitude * np.cos(pr["omega"] * s.t)) / amplitude)
    # the trapezoidal rule's period error, (omega dt)^2 / 12 = 1.3 %, costs 8 % of the amplitude in a period
    assert worst < 0.12, worst
    assert abs(s.energies()["total"] / e0 - 1.0) < 0.01
    assert s.record.newton_iterations == round(period / dt)  # linear: one Newton step each


@pytest.mark.parallel
def test_a_step_newton_cannot_take_is_halved(petsc_options):
    petsc_options(fempm_implicit_snes_max_it=1)  # too few for this nonlinear step
    s = cook_solver(6.0, max_cuts=2)
    with pytest.raises(SimulationError, match=r"did not converge \(SNES DIVERGED_MAX_IT.*after 2 halving\(s\)"):
        s.step(1.0)
    assert s.record.cut_steps == 2 and s.t == 0.0


@pytest.mark.parallel
def test_a_free_body_in_a_quasi_static_step_has_a_singular_tangent():
    import dolfinx.fem
    import dolfinx.mesh

    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 6, 6, dolfinx.mesh.CellType.triangle)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    p = fempm.create_particles(mesh, 4)
    s = ExplicitSolver(V, p, [NeoHookean(100.0, 0.3)], loads=Loads(body_force=(0.0, -1.0)),
                       options=StepOptions(**QUASI_STATIC))
    with pytest.raises(SimulationError, match=r"singular tangent in the quasi-static step \(3 null pivot"):
        s.step(0.1)


@pytest.mark.parametrize("options, message", [
    ({"integrator": "implicitly"}, r"unknown option integrator='implicitly'; expected explicit or implicit"),
    ({"integrator": "implicit", "dynamics": "static"}, r"unknown option dynamics='static'"),
    ({"integrator": "implicit", "newmark_beta": 0.6}, r"newmark_beta=0.6 must lie in \(0, 1/2\]"),
    ({"integrator": "implicit", "newmark_gamma": 0.4}, r"newmark_gamma=0.4 must lie in \[1/2, 1\]"),
    ({"integrator": "implicit", "tangent": "numeric"}, r"unknown option tangent='numeric'"),
    ({"integrator": "implicit", "load_ramp": 0.0}, r"load_ramp=0.0 must be a positive time"),
])
def test_bad_implicit_options(options, message):
    with pytest.raises(ValueError, match=message):
        StepOptions(**options)


class SmallStrain:
    """A user law with a stress and no tangent: LinearElastic(E = 1, nu = 1/3) written out."""

    history = ()

    def stress(self, F, L, sigma, dt, rho):
        lam, mu = 0.75, 0.375  # E = 1, nu = 1/3
        eps = 0.5 * (F + np.swapaxes(F, 1, 2)) - np.eye(F.shape[1])
        return lam * np.trace(eps, axis1=1, axis2=2)[:, None, None] * np.eye(F.shape[1]) + 2 * mu * eps

    def wave_speed(self, F, rho):
        return np.sqrt(1.5 / rho)

    def energy_density(self, F):
        return np.zeros(len(F))


def test_a_law_without_tangent_runs_with_the_finite_difference_one_asked_for_by_name():
    scene = cook_membrane(h=4.0, nu=1 / 3, load=1e-3)
    scene.materials = [SmallStrain()]
    scene.options = StepOptions(**QUASI_STATIC)
    with pytest.raises(TypeError, match=r"SmallStrain has no tangent.*StepOptions\(tangent='finite-difference'\)"):
        scene.solver().step(1.0)
    scene = cook_membrane(h=4.0, nu=1 / 3, load=1e-3)
    scene.materials = [SmallStrain()]
    scene.options = StepOptions(**QUASI_STATIC, tangent="finite-difference")
    s = scene.solver()
    s.step(1.0)
    analytic = cook_solver(4.0)
    analytic.step(1.0)
    np.testing.assert_allclose(corner_displacement(s.particles), corner_displacement(analytic.particles), rtol=1e-9)
    assert s.implicit.last.iterations == analytic.implicit.last.iterations


def test_implicit_step_refuses_what_it_cannot_take():
    with pytest.raises(ValueError, match=r"lumped or consistent mass, not FMPM"):
        StepOptions(**QUASI_STATIC, mass="fmpm2")
    with pytest.raises(ValueError, match=r"position='particle' does not apply"):
        StepOptions(**QUASI_STATIC, position="particle")
    s = cook_solver(6.0)
    with pytest.raises(ValueError, match=r"the implicit step needs a time step dt > 0"):
        s.step()
