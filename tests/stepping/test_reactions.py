"""The reactions of the grid conditions (fempm.stepping.reactions): a run whose only external
actions are its loads, its supports and walls and its colliders keeps its momentum balance to
round-off on every grid, mass model, scheme and cell type, and the reaction a support reports is
the weight it carries."""

import dolfinx.mesh as dm
import numpy as np
import pytest
from mpi4py import MPI

import fempm
from fempm.boundary import absorbing, fixed, friction, slip, tagged
from fempm.colliders import Collider, box
from fempm.materials import LinearElastic
from fempm.scene import Scene, run
from fempm.stepping import Loads, StepOptions
from fempm.stepping.contact import Contact
from fempm.stepping.health import Health, HealthMonitor

comm = MPI.COMM_WORLD
RHO, G, HEIGHT = 1000.0, 10.0, 0.2
#: the blocks start from their weight's stress, which a LinearElastic law's energy (of F) does not see
NO_ENERGY_CHECK = Health(energy_tolerance=None)


def _floor(x):
    return np.isclose(x[1], 0.0)


def _sides(x):
    return np.isclose(x[0], 0.0) | np.isclose(x[0], 1.0)


def _tagged_box(V):
    """Slip on the floor and the sides tagged as one wall: the corners' averaged normals make it
    a wall of a normal per node (not an axis), applied on the velocities."""
    mesh = V.mesh
    facets = dm.locate_entities_boundary(mesh, 1, lambda x: _floor(x) | _sides(x))
    tags = dm.meshtags(mesh, 1, facets, np.full(len(facets), 1, dtype=np.int32))
    wall = tagged(V, tags, 1, "slip")
    assert wall.axis is None
    return [wall]


# the grid conditions of each case (V -> [conditions]); every case has the floor y = 0
WALLS = {
    "fixed": lambda V: [fixed(V, _floor)],
    "slip": lambda V: [slip(V, _floor, (0.0, -1.0)), slip(V, _sides, (1.0, 0.0))],
    "slip-tagged": _tagged_box,
    "friction": lambda V: [friction(V, _floor, (0.0, -1.0), 0.3)],
    "friction-gap": lambda V: [friction(V, _floor, (0.0, -1.0), 0.3, gap=0.05)],
    "absorbing": lambda V: [fixed(V, _floor), absorbing(V, rho=RHO, cp=10.0, cs=5.0, where=_sides)],
}

# name: (walls, options, cell type, degree, variant, extra scene arguments)
CASES = {
    "lumped": ("fixed", {}, "quadrilateral", 1, None),
    "slip": ("slip", {}, "quadrilateral", 1, None),
    "slip-tagged": ("slip-tagged", {}, "triangle", 1, None),
    "friction": ("friction", {}, "quadrilateral", 1, None),
    "friction-gap": ("friction-gap", {}, "triangle", 1, None),
    "absorbing": ("absorbing", {}, "quadrilateral", 1, None),
    "USF": ("fixed", {"scheme": "USF"}, "quadrilateral", 1, None),
    "MUSL-PIC": ("slip", {"scheme": "MUSL", "flip": 0.0}, "triangle", 1, None),
    "damped": ("fixed", {"damping": 5.0}, "quadrilateral", 1, None),
    "consistent": ("fixed", {"mass": "consistent"}, "triangle", 1, None),
    "consistent-slip": ("slip", {"mass": "consistent"}, "quadrilateral", 1, None),
    "fmpm": ("friction", {"mass": "fmpm2"}, "quadrilateral", 1, None),
    "gimp": ("slip", {"domain": "gimp"}, "quadrilateral", 1, None),
    "cpdi": ("fixed", {"domain": "cpdi1", "mass": "fmpm1"}, "triangle", 1, None),
    "P2-consistent": ("fixed", {"mass": "consistent"}, "triangle", 2, None),
    "bernstein": ("slip", {}, "triangle", 2, "bernstein"),
    "numpy-step": ("friction", {}, "quadrilateral", 1, None),
    "numpy-consistent": ("slip", {"mass": "consistent"}, "triangle", 1, None),
}


def resting_block(walls: str, options: dict, cell: str = "quadrilateral", degree: int = 1, variant=None,
                  t_end: float = 0.2, contact: bool = False, collider: bool = False, left: float = 0.3) -> Scene:
    """An elastic block [left, left + 0.4] x [0, 0.2] resting on the floor of a [0, 1] x [0, 0.5]
    box under gravity, its weight's stress given (with ``contact`` two blocks side by side, two
    velocity fields; with ``collider`` a box pressing on its top)."""
    mesh = dm.create_rectangle(comm, [[0.0, 0.0], [1.0, 0.5]], [10, 5], getattr(dm.CellType, cell))
    p = fempm.create_particles(mesh, 4, density=RHO,
                               where=lambda x: (x[0] > left) & (x[0] < left + 0.4) & (x[1] < HEIGHT))
    sigma = np.zeros((len(p), 2, 2))
    sigma[:, 1, 1] = -RHO * G * (HEIGHT - p.x[:, 1])
    p.fields["sigma"] = sigma
    if contact:
        p.fields["body"] = (p.x[:, 0] > left + 0.2).astype(np.int32)
    opts = {"cfl": 0.4, "flip": 0.9, **options}
    colliders = [Collider(box((0.4, HEIGHT + 0.02), (0.6, 0.3)), velocity=(0.0, -0.05))] if collider else []
    return Scene(name="resting", mesh=mesh, particles=p, materials=[LinearElastic(1.0e5, 0.3)] * (2 if contact else 1),
                 t_end=t_end, frames=0, bcs=WALLS[walls], loads=Loads(body_force=(0.0, -G)),
                 options=StepOptions(**opts), degree=degree, variant=variant,
                 contact=Contact(friction=0.2) if contact else None, colliders=colliders)


def _run(scene: Scene, compiled=None) -> tuple[HealthMonitor, float]:
    solver = scene.solver()
    solver.compiled = compiled
    monitor = HealthMonitor(solver, NO_ENERGY_CHECK)
    mass = comm.allreduce(float(scene.particles.mass.sum()))
    while solver.t < scene.t_end - 1e-12:
        dt = solver.step(dt_max=scene.t_end - solver.t)
        monitor.after_step(dt, solver.energies())
    return monitor, mass


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parallel(only=("lumped", "slip-tagged", "friction-gap", "absorbing", "consistent", "gimp",
                            "P2-consistent"))
def test_the_supports_take_what_the_body_does_not(case):
    """The momentum balance closes to round-off with the reactions (it was off by the whole
    impulse of gravity: the drift grew as g t over the momentum scale), and the floor carries the
    block's weight: its reaction over the run is -M g t within a few per cent (the block settles
    about its loaded state). Particle domains (GIMP, CPDI) that reach below the floor lose the part
    of their basis beyond the mesh: a drift of 1e-7 that is theirs, not the walls'."""
    walls, options, cell, degree, variant = CASES[case]
    compiled = False if case.startswith("numpy") else None
    left = 0.0 if case == "absorbing" else 0.3  # against the absorbing side, which takes its thrust
    monitor, mass = _run(resting_block(walls, options, cell, degree, variant, left=left), compiled)
    assert monitor.drift < (1e-6 if "domain" in options else 1e-11)
    reaction = monitor.reactions
    assert reaction[1] == pytest.approx(-mass * G * 0.2, rel=0.06)
    if case != "absorbing":
        assert abs(reaction[0]) < 0.06 * mass * G * 0.2


@pytest.mark.parametrize("compiled", [None, False], ids=["compiled", "numpy"])
@pytest.mark.parallel(only=("compiled",))
def test_two_fields_on_a_wall_balance_with_their_reactions(compiled):
    """Contact grids: two blocks side by side, each its own field, on a frictional floor."""
    monitor, mass = _run(resting_block("friction", {"scheme": "MUSL"}, contact=True), compiled)
    assert monitor.drift < 1e-11
    assert monitor.reactions[1] == pytest.approx(-mass * G * 0.2, rel=0.06)


@pytest.mark.parallel
def test_a_collider_on_a_supported_body_is_counted_once():
    """A box pressing the block onto the fixed floor: the colliders' impulse and the floor's
    reaction are counted apart (the nodes both touch are the collider's), the balance closes."""
    scene = resting_block("fixed", {"scheme": "MUSL"}, collider=True, t_end=0.3)
    solver = scene.solver()
    monitor = HealthMonitor(solver, NO_ENERGY_CHECK)
    while solver.t < scene.t_end - 1e-12:
        dt = solver.step(dt_max=scene.t_end - solver.t)
        monitor.after_step(dt, solver.energies())
    assert np.linalg.norm(solver.collisions.impulse[0]) > 0.0  # it pressed
    assert monitor.drift < 1e-11


def test_3d_block_on_a_fixed_floor():
    mesh = dm.create_box(comm, [[0.0, 0.0, 0.0], [1.0, 1.0, 0.5]], [4, 4, 2], dm.CellType.hexahedron)
    p = fempm.create_particles(mesh, 8, density=RHO, where=lambda x: (x[2] < 0.25) & (x[0] > 0.25) & (x[0] < 0.75))
    sigma = np.zeros((len(p), 3, 3))
    sigma[:, 2, 2] = -RHO * G * (0.25 - p.x[:, 2])
    p.fields["sigma"] = sigma
    scene = Scene(name="block3", mesh=mesh, particles=p, materials=[LinearElastic(1.0e5, 0.3)], t_end=0.15,
                  frames=0, bcs=lambda V: [fixed(V, lambda x: np.isclose(x[2], 0.0))],
                  loads=Loads(body_force=(0.0, 0.0, -G)), options=StepOptions(cfl=0.4, flip=0.9))
    monitor, mass = _run(scene)
    assert monitor.drift < 1e-11
    assert monitor.reactions[2] == pytest.approx(-mass * G * 0.15, rel=0.06)


@pytest.mark.parallel
def test_run_reports_the_reaction_impulse_and_a_round_off_drift():
    """run(): the summary's reaction_impulse, and its momentum_drift at round-off (the beam with a
    fixed end reported 0.42, the wave 0.81, the footing 57.8)."""
    scene = resting_block("fixed", {})
    scene.health = NO_ENERGY_CHECK
    summary = run(scene, progress=False)
    h = summary["health"]
    assert h["momentum_drift"] < 1e-11
    assert len(h["reaction_impulse"]) == 2 and h["reaction_impulse"][1] < 0.0


@pytest.mark.parametrize("walls, options", [
    ("fixed", {}), ("slip", {"mass": "consistent"}), ("fixed", {"flip": 0.0}), ("slip", {"flip": 0.5}),
], ids=["lumped", "consistent", "PIC", "blend"])
@pytest.mark.parallel(only=("lumped", "consistent"))
def test_newmark_steps_count_their_reactions(walls, options):
    """Implicit Newmark steps: the held rows' residual and the projection's balance (fempm.implicit.step
    ``_count_reactions``) close the momentum balance (the cantilever reported 22.1), and the floor
    carries the block's weight."""
    scene = resting_block(walls, {"integrator": "implicit", "dynamics": "newmark", **options})
    solver = scene.solver()
    monitor = HealthMonitor(solver, NO_ENERGY_CHECK)
    mass = comm.allreduce(float(scene.particles.mass.sum()))
    for _ in range(20):
        solver.step(0.01)
        monitor.after_step(0.01, solver.energies())
    assert monitor.drift < 1e-10
    assert monitor.reactions[1] == pytest.approx(-mass * G * 0.2, rel=0.06)
