"""Bad inputs to the materials, boundary conditions, particles, scenes and the step: a clear
error naming the argument, not a silent NaN, an endless run or a step that goes backwards."""

import dataclasses

import dolfinx.fem
import dolfinx.mesh as dm
import numpy as np
import pytest
from mpi4py import MPI

import fempm
from fempm.boundary import slip
from fempm.materials import LinearElastic, NeoHookean, NewtonianTait
from fempm.scenes import vibrating_bar
from fempm.stepping import ExplicitSolver, StepOptions

comm = MPI.COMM_SELF


@pytest.mark.parametrize("make, message", [
    (lambda: NeoHookean(float("nan"), 0.3), "needs E > 0"),
    (lambda: LinearElastic(float("inf"), 0.3), "needs E > 0"),
    (lambda: NeoHookean(1.0, float("nan")), "-1 < nu < 0.5"),
    (lambda: NewtonianTait(rho0=1.0, kappa=-5.0), "kappa > 0"),
    (lambda: NewtonianTait(rho0=0.0), "rho0 > 0"),
    (lambda: NewtonianTait(rho0=1.0, gamma=float("nan")), "gamma > 1"),
    (lambda: NewtonianTait(rho0=1.0, viscosity=-1.0), "viscosity >= 0"),
])
def test_bad_material_constants(make, message):
    with pytest.raises(ValueError, match=message):
        make()


@pytest.fixture(scope="module")
def mesh():
    return dm.create_unit_square(comm, 4, 4)


@pytest.mark.parametrize("normal", [(0.0, 0.0), (np.nan, 1.0), (1.0, 0.0, 0.0)])
def test_bad_slip_normals(mesh, normal):
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    with pytest.raises(ValueError, match="slip needs a finite, non-zero normal with 2 components"):
        slip(V, lambda x: x[0] < 1e-9, normal)


@pytest.mark.parametrize("field, value", [("mass", np.inf), ("volume", np.inf), ("mass", np.nan)])
def test_non_finite_mass_or_volume(mesh, field, value):
    kw = {"mass": 1.0, "volume": 1.0, field: value}
    with pytest.raises(ValueError, match=f"non-positive or non-finite {field}"):
        fempm.Particles(mesh, [[0.5, 0.5]], kw["mass"], kw["volume"])


def _solver(mesh, material=None, n=4):
    p = fempm.create_particles(mesh, n, density=1.0) if n else fempm.Particles(mesh, np.zeros((0, 2)), 1.0, 1.0)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    return ExplicitSolver(V, p, [material or NeoHookean(10.0, 0.3)], options=StepOptions())


@pytest.mark.parametrize("dt", [-1e-3, 0.0, np.nan, np.inf])
def test_step_needs_a_positive_finite_dt(mesh, dt):
    with pytest.raises(ValueError, match="must be a positive, finite time step"):
        _solver(mesh).step(dt)


def test_step_without_particles(mesh):
    with pytest.raises(ValueError, match="there are no particles"):
        _solver(mesh, n=0).step()


def test_no_stable_step_without_wave_speed_and_motion(mesh):
    """A law with wave speed 0 and particles at rest: no time scale (it was dt = 5e298)."""

    @dataclasses.dataclass(frozen=True)
    class Dust(LinearElastic):
        def wave_speed(self, F, rho):
            return np.zeros(len(F))

    solver = _solver(mesh, Dust(1.0, 0.0))
    with pytest.raises(ValueError, match="no stable time step"):
        solver.step()
    assert solver.step(dt_max=1e-3) == 1e-3  # a bound makes it a step


@pytest.mark.parametrize("t_end", [0.0, -1.0, np.nan, np.inf])
def test_scene_needs_a_positive_finite_end_time(t_end):
    with pytest.raises(ValueError, match="must be a positive, finite time"):
        vibrating_bar(cells=4, t_end=t_end, comm=comm)


def test_duplicate_or_malformed_ids(mesh):
    with pytest.raises(ValueError, match=r"particle ids must be unique over all ranks; repeated: \[7\]"):
        fempm.Particles(mesh, [[0.2, 0.2], [0.7, 0.7]], 1.0, 1.0, ids=[7, 7])
    with pytest.raises(ValueError, match="ids must be 2 integers"):
        fempm.Particles(mesh, [[0.2, 0.2], [0.7, 0.7]], 1.0, 1.0, ids=[0.5, 1.5])


@pytest.mark.parametrize("compiled", [False, True])
def test_a_body_without_material_is_refused_by_both_steps(mesh, compiled):
    solver = _solver(mesh)
    solver.compiled = compiled
    solver.particles.fields["body"][:] = 1  # one material only: it was stress-free in the generic step
    with pytest.raises(ValueError, match=r"body index outside the 1 material\(s\)"):
        solver.step()
