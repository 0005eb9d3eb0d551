"""Clear errors from the explicit loop, and a scene assembling only the terms it declares."""

import dolfinx.mesh as dm
import fempm
import numpy as np
import pytest
from mpi4py import MPI

from fempm.boundary import slip
from fempm.materials import LinearElastic
from fempm.scene import Scene, run
from fempm.stepping import Loads, SimulationError, StepOptions
from fempm.stepping.lumped import PointGrid

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD


def block_scene(v=(0.0, 0.0), loads=None, options=None, E=100.0, bcs=None, t_end=0.05):
    mesh = dm.create_unit_square(comm, 8, 8)
    p = fempm.create_particles(mesh, 4, density=1.0, cells=lambda x: (x[0] > 0.25) & (x[0] < 0.75) & (x[1] < 0.5))
    p.fields["v"] = np.tile(np.asarray(v, float), (len(p), 1))
    return Scene("block", mesh, p, [LinearElastic(E, 0.3)], t_end=t_end, loads=loads or Loads(),
                 options=options or StepOptions(), bcs=bcs)


def test_unknown_options_and_cfl_above_one():
    with pytest.raises(ValueError, match="unknown option scheme='USX'"):
        StepOptions(scheme="USX")
    with pytest.raises(ValueError, match="unknown option mass='diag'"):
        StepOptions(mass="diag")
    with pytest.raises(ValueError, match="CFL number above 1"):
        StepOptions(cfl=1.5)


def test_time_step_above_stability_limit_is_refused():
    solver = block_scene().solver()
    with pytest.raises(SimulationError, match=r"step 0, t = 0: time step .* exceeds the stability limit"):
        solver.step(10.0 * solver.stable_dt())


def test_a_given_step_near_the_limit_is_checked_exactly():
    """The compiled step checks a given dt against a lower bound of the stable time first
    (at rest 1/sqrt(2) of it) and against the time itself only above the bound: a dt just
    below the limit is taken, one just above is refused."""
    solver = block_scene().solver()
    limit = solver.stable_dt() / solver.options.cfl
    solver.step(0.99 * limit)
    assert isinstance(solver.grid, PointGrid) and solver.step_count == 1
    limit = solver.stable_dt() / solver.options.cfl
    with pytest.raises(SimulationError, match="exceeds the stability limit"):
        solver.step(1.01 * limit)


def test_inverted_deformation_is_reported():
    solver = block_scene().solver()
    solver.particles.fields["F"][:, 0, 0] = -1.0  # J < 0 already
    with pytest.raises(SimulationError, match=r"step 0, t = 0: inverted deformation J <= 0 at particle\(s\) \[\d+"):
        solver.step()


def test_non_finite_state_is_reported():
    solver = block_scene().solver()
    if len(solver.particles):
        solver.particles.fields["v"][0] = np.nan
    with pytest.raises(SimulationError, match="non-finite state at particle"):
        solver.step()


def test_particle_leaving_the_mesh():
    scene = block_scene(v=(0.0, -30.0), t_end=0.2)  # falls through the bottom
    with pytest.raises(fempm.OutsideMeshError, match="outside the mesh"):
        run(scene, None, progress=False)


def test_gravity_is_assembled_only_when_declared():
    r0 = run(block_scene(), None, progress=False)
    assert r0["terms_assembled"] == {"internal": r0["steps"]}
    g = (0.0, -10.0)
    r1 = run(block_scene(loads=Loads(body_force=g)), None, progress=False)
    assert r1["terms_assembled"] == {"internal": r1["steps"], "body_force": r1["steps"]}
    # free fall of the whole block: momentum changes by M g t exactly (no boundary)
    p = r1["history"][-1]
    M = comm.allreduce(r1["solver"].particles.mass.sum())
    assert p["momentum_y"] == pytest.approx(M * g[1] * p["t"], rel=1e-12)


def test_slip_wall_along_any_normal():
    """A block sliding along a wall whose normal is (1, 1)/sqrt(2) keeps v . n = 0 on the grid."""
    n = np.array([1.0, 1.0]) / np.sqrt(2)

    def bcs(V):
        return [slip(V, lambda x: np.ones(x.shape[1], dtype=bool), n)]  # every node: a tilted plane

    r = run(block_scene(v=(0.3, 0.1), bcs=bcs), None, progress=False)
    v = r["solver"].grid_velocity
    assert np.abs(v @ n).max() < 1e-14
    assert np.abs(v @ np.array([1.0, -1.0])).max() > 0.1  # tangential motion survives


def test_unknown_domain_and_cpdi2_without_corners_are_errors():
    with pytest.raises(ValueError, match="unknown option domain"):
        StepOptions(domain="bspline")
    solver = block_scene(options=StepOptions(domain="cpdi2")).solver()  # particles without corners
    with pytest.raises(ValueError, match="CPDI2 needs particle corners"):
        solver.step()


#: the step implementations a bare step() loop can take: the compiled lumped and consistent
#: steps, the generic step (compiled=False) and the contact step
STEPS = {"lumped": dict(options=StepOptions()), "consistent": dict(options=StepOptions(mass="consistent")),
         "generic": dict(options=StepOptions(), compiled=False),
         "gimp": dict(options=StepOptions(domain="gimp"))}


def _bare_solver(kind: str):
    from fempm.stepping import ExplicitSolver

    scene = block_scene()
    V = scene.space()
    opts = STEPS[kind]
    return ExplicitSolver(V, scene.particles, scene.materials, options=opts["options"],
                          compiled=opts.get("compiled"))


@pytest.mark.parametrize("kind", sorted(STEPS))
def test_a_bare_step_refuses_a_particle_at_1e200_metres_per_second(kind):
    """|v|^2 overflows: the kinetic energy is inf and the stable step underflows to 0. Set
    before the first step and between steps (the arrays the step already checked, changed in
    place), each step implementation refuses it instead of stepping on with t = 0."""
    for when in ("before", "between"):
        solver = _bare_solver(kind)
        if when == "between":
            solver.step()
        t = solver.t
        fast = solver.particles.ids == comm.allreduce(int(solver.particles.ids.min(initial=10**9)), op=MPI.MIN)
        solver.particles.fields["v"][fast] = [1e200, 0.0]
        with pytest.raises(SimulationError, match="non-finite state|time step collapse"):
            for _ in range(3):
                solver.step()
        assert solver.t == t


@pytest.mark.parametrize("kind", sorted(STEPS))
def test_a_bare_step_refuses_an_inverted_particle_made_between_steps(kind):
    solver = _bare_solver(kind)
    solver.step()
    solver.particles.fields["F"][:1, 0, :] *= -1.0  # in place: J < 0 on the first particle of each rank
    with pytest.raises(SimulationError, match=r"inverted deformation J <= 0|non-finite"):
        solver.step()
