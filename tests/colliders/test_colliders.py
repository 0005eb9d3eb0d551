"""Rigid colliders (fempm.colliders): the shapes' signed distances and normals, the momentum the
body takes equal to minus the collider's impulse to round-off (compiled and numpy steps,
consistent mass, 1 and 2 ranks), a moving box pushing a block at its speed, a disk rolling down
a tilted plane collider at (2/3) g sin(theta), the reaction in energies.csv and summary.json, a
resumed run, bad input named."""

import csv
import json

import dolfinx.mesh as dm
import numpy as np
import pytest
from mpi4py import MPI

import fempm
from fempm.boundary import friction
from fempm.colliders import Collider, box, disk, plane, polygon
from fempm.materials import LinearElastic
from fempm.scene import Scene, run
from fempm.scenes.incline import incline
from fempm.stepping import Loads, StepOptions


RNG = np.random.default_rng(7)


# -- shapes -------------------------------------------------------------------------------------
def _fd_normal(shape, x, eps=1e-6):
    d = x.shape[1]
    return np.stack([(shape.distance(x + eps * e) - shape.distance(x - eps * e)) / (2 * eps) for e in np.eye(d)], 1)


@pytest.mark.parametrize("name", ["plane", "disk", "sphere", "box2", "box3", "square", "triangle"])
def test_distances_and_normals(name):
    """Distances against closed forms at chosen points; normals = the distance's gradient (central
    differences) at random points, unit length."""
    shapes = {
        "plane": (plane((1.0, 2.0), (0.0, 3.0)), [[5.0, 2.5], [0.0, 1.0]], [0.5, -1.0]),
        "disk": (disk((0.0, 0.0), 1.0), [[2.0, 0.0], [0.0, 0.5]], [1.0, -0.5]),
        "sphere": (disk((0.0, 0.0, 1.0), 0.5), [[0.0, 0.0, 3.0], [0.1, 0.0, 1.0]], [1.5, -0.4]),
        "box2": (box((0.0, 0.0), (2.0, 1.0)), [[3.0, 2.0], [1.0, 0.25], [-1.0, 0.5]], [np.sqrt(2), -0.25, 1.0]),
        "box3": (box((0, 0, 0), (1, 1, 1)), [[2.0, 2.0, 2.0], [0.5, 0.5, 0.9]], [np.sqrt(3), -0.1]),
        "square": (polygon([[0, 0], [1, 0], [1, 1], [0, 1]]), [[2.0, 0.5], [0.5, 0.2], [-3.0, -4.0]], [1.0, -0.2, 5.0]),
        "triangle": (polygon([[0, 0], [0, 2], [2, 0]]), [[1.0, 1.0 + 1e-9], [0.2, 0.5], [-1.0, 1.0]],
                     [0.0, -0.2, 1.0]),
    }
    shape, points, expected = shapes[name]
    assert shape.distance(np.array(points, dtype=float)) == pytest.approx(expected, abs=1e-8)
    d = shape.dim
    x = RNG.uniform(-3.0, 3.0, size=(200, d))
    x = x[np.abs(shape.distance(x)) > 1e-3]
    fd = _fd_normal(shape, x)
    smooth = np.abs(np.linalg.norm(fd, axis=1) - 1.0) < 1e-6  # away from the kinks of the distance
    assert np.count_nonzero(smooth) > 100
    n = shape.normal_at(x)
    assert np.linalg.norm(n, axis=1) == pytest.approx(1.0, abs=1e-12)
    assert np.abs(n[smooth] - fd[smooth]).max() < 1e-5


# -- a block and a box ------------------------------------------------------------------------
def pushed_block(comm=MPI.COMM_WORLD, floor=False, speed=0.5, mu=0.3, t_end=0.3, options=None,
                 velocity=None) -> Scene:
    """An elastic block [0.4, 0.6] x [0, 0.1] (on a frictional floor with gravity, ``floor``) or
    [0.4, 0.6] x [0.2, 0.3] (free), pushed in x by a box collider moving at ``speed`` from x = 0.35."""
    mesh = dm.create_rectangle(comm, [[0.0, 0.0], [1.0, 0.5]], [20, 10], dm.CellType.quadrilateral)
    y0 = 0.0 if floor else 0.2
    p = fempm.create_particles(mesh, 4, density=1000.0,
                               cells=lambda x: (x[0] > 0.4) & (x[0] < 0.6) & (x[1] > y0) & (x[1] < y0 + 0.1))
    if floor:  # at rest under its weight
        sigma = np.zeros((len(p), 2, 2))
        sigma[:, 1, 1] = -1000.0 * 10.0 * (0.1 - p.x[:, 1])
        p.fields["sigma"] = sigma
        p.fields["sigma_zz"] = 0.3 * sigma[:, 1, 1]
    shape = box((0.25, y0 - 0.05 if not floor else 0.02), (0.36, y0 + 0.15))
    bcs = (lambda V: [friction(V, lambda x: np.isclose(x[1], 0.0), (0.0, -1.0), mu, gap=0.025)]) if floor else None
    return Scene(name="pushed", mesh=mesh, particles=p, materials=[fempm.VonMises(1.0e5, 0.3) if floor else
                                                                   LinearElastic(1.0e5, 0.3)],
                 t_end=t_end, frames=0, bcs=bcs, loads=Loads(body_force=(0.0, -10.0)) if floor else Loads(),
                 options=options or StepOptions(scheme="MUSL", flip=0.9 if floor else 1.0, cfl=0.4),
                 colliders=[Collider(shape, velocity=velocity or (speed, 0.0))])


def _momentum(p):
    return p.comm.allreduce(p.mass @ p.fields["v"])


@pytest.mark.parametrize("variant", ["compiled", "numpy step", "consistent mass", "PIC"])
@pytest.mark.parallel(only=("compiled", "consistent mass"))
def test_the_body_takes_minus_the_colliders_impulse(variant):
    """No other force on the block: its momentum is minus the impulse the collider reports, to
    round-off of the momentum it took, on every path."""
    options = {"consistent mass": StepOptions(scheme="MUSL", mass="consistent", cfl=0.4),
               "PIC": StepOptions(scheme="USL", flip=0.0, cfl=0.4)}.get(variant)
    scene = pushed_block(options=options)
    solver = scene.solver()
    solver.compiled = False if variant == "numpy step" else None
    p0 = _momentum(scene.particles)
    while solver.t < 0.3:
        solver.step()
    impulse = solver.collisions.impulse[0]
    gained = _momentum(scene.particles) - p0
    assert impulse[0] < -0.5  # it pushed (the block's mass is 20 kg, the box at 0.5 m/s)
    assert np.abs(gained + impulse).max() <= 1e-10 * np.abs(impulse).max()
    assert solver.collisions.displacement[0] == pytest.approx([0.5 * solver.t, 0.0], rel=1e-12)


@pytest.mark.parametrize("cell", ["triangle", "tetrahedron", pytest.param("hexahedron", marks=pytest.mark.slow)])
@pytest.mark.parallel(only=("tetrahedron",))
def test_the_impulse_balance_on_every_cell_type(cell):
    """A disk (a sphere in 3D) collider moving at 0.5 m/s into a free block on simplices and
    hexahedra: the block's momentum is minus the collider's impulse to round-off."""
    comm = MPI.COMM_WORLD
    if cell == "triangle":
        mesh = dm.create_rectangle(comm, [[0.0, 0.0], [1.0, 0.5]], [20, 10], dm.CellType.triangle)
    else:
        mesh = dm.create_box(comm, [[0.0, 0.0, 0.0], [1.0, 0.5, 0.5]], [10, 5, 5], getattr(dm.CellType, cell))
    d = mesh.geometry.dim
    p = fempm.create_particles(mesh, 4 if d == 2 else 8, density=1000.0,
                               cells=lambda x: (x[0] > 0.4) & (x[0] < 0.6) & (np.abs(x[1] - 0.25) < 0.1)
                               & ((np.abs(x[2] - 0.25) < 0.1) if d == 3 else True))
    centre = (0.25, 0.25, 0.25)[:d]
    velocity = (0.5, 0.0, 0.0)[:d]
    scene = Scene(name="sphere", mesh=mesh, particles=p, materials=[LinearElastic(1.0e5, 0.3)], t_end=0.3,
                  frames=0, colliders=[Collider(disk(centre, 0.1), velocity=velocity)])
    solver = scene.solver()
    p0 = _momentum(p)
    while solver.t < 0.3:
        solver.step()
    impulse = solver.collisions.impulse[0]
    assert impulse[0] < -0.1
    assert np.abs(_momentum(p) - p0 + impulse).max() <= 1e-10 * np.abs(impulse).max()


@pytest.mark.parallel
def test_two_ranks_as_one():
    """The pushed block's collider impulse on the ranks of COMM_WORLD equals the one-rank run's."""
    def impulse(comm):
        solver = pushed_block(comm).solver()
        while solver.t < 0.2:
            solver.step()
        return solver.collisions.impulse[0]
    assert impulse(MPI.COMM_WORLD) == pytest.approx(impulse(MPI.COMM_SELF), rel=1e-9, abs=1e-12)


def test_a_moving_box_pushes_a_block_at_its_speed(tmp_path):
    """A block on a floor with friction 0.3 pushed by a box at 0.2 m/s moves at 0.2 m/s once pushed
    (the slope of its centre's path from t = 0.4 to 1, within 2 %); the collider's force balances
    the floor's friction, mu m g = 60 N (mean within 10 %), written as collider_force_0_x to
    energies.csv."""
    out = MPI.COMM_WORLD.bcast(str(tmp_path), root=0)
    scene = pushed_block(floor=True, speed=0.2, t_end=1.0)
    path = []

    def watch(solver):
        p = solver.particles
        path.append((solver.t, *p.comm.allreduce(np.array([p.mass @ p.x[:, 0], p.mass.sum()]))))

    summary = run(scene, out, progress=False, callback=watch)
    t, mx, m = np.array(path).T
    late = t > 0.4
    assert np.polyfit(t[late], mx[late] / m[late], 1)[0] == pytest.approx(0.2, rel=0.02)
    with open(f"{out}/energies.csv") as f:
        rows = list(csv.DictReader(f))
    force = np.array([float(r["collider_force_0_x"]) for r in rows])
    times = np.array([float(r["t"]) for r in rows])
    assert -np.mean(force[times > 0.4]) == pytest.approx(0.3 * 20.0 * 10.0, rel=0.1)
    if MPI.COMM_WORLD.rank == 0:
        with open(f"{out}/summary.json") as f:
            written = json.load(f)["colliders"][0]
        assert written["displacement"] == pytest.approx([0.2 * 1.0, 0.0], rel=1e-9)
    assert summary["status"] == "completed"


@pytest.mark.parallel
def test_the_run_counts_the_colliders_impulse_and_work():
    """run(): the health figures count what the collider took and the work it did (the free
    block's momentum drift at round-off, its energy within the budget)."""
    summary = run(pushed_block(), progress=False)
    assert summary["health"]["momentum_drift"] < 1e-10
    assert 0.9 < summary["health"]["energy_ratio"] < 1.05  # (the explicit step oscillates about it)
    assert summary["colliders"][0]["work"] > 0.0


@pytest.mark.parallel
def test_a_resumed_run_continues_the_colliders(tmp_path):
    """Fixed steps: a run to 0.15 and its continuation to 0.3 end where the whole run does, the
    collider's displacement and impulse included."""
    base = MPI.COMM_WORLD.bcast(str(tmp_path), root=0)

    def scene(t_end):
        s = pushed_block(t_end=t_end)
        s.dt = 2.0**-11
        return s

    whole = run(scene(0.3), base + "/whole", progress=False)
    run(scene(0.15), base + "/part", progress=False, checkpoint_every=64)
    resumed = run(scene(0.3), base + "/part", progress=False, resume=True)
    for key in ("impulse", "displacement", "work"):
        assert resumed["colliders"][0][key] == pytest.approx(whole["colliders"][0][key], rel=1e-9, abs=1e-14)
    assert resumed["health"]["momentum_drift"] < 1e-10


# -- the rolling disk -------------------------------------------------------------------------
@pytest.mark.parametrize("mu", [0.2, pytest.param(1.0, marks=pytest.mark.slow)])
def test_a_disk_rolls_down_a_tilted_plane_collider(mu):
    """A disk (8 cells per radius) on a plane collider at 30 degrees, gravity vertical: it rolls
    at (2/3) g sin(theta) within 2 % from mu = 0.2 (just above tan(theta)/3 = 0.19) on."""
    result = run(incline(body="disk", plane="collider", friction=mu, cells=8, frames=0), progress=False)
    assert result["acceleration"] == pytest.approx(2.0 / 3.0 * 9.81 * 0.5, rel=0.02)


def test_a_disk_slides_down_a_plane_collider_below_the_threshold():
    """mu = 0.1 < tan(theta)/3: it slides at g (sin - mu cos) within 2 %."""
    result = run(incline(body="disk", plane="collider", friction=0.1, cells=8, frames=0), progress=False)
    assert result["acceleration"] == pytest.approx(9.81 * (0.5 - 0.1 * np.cos(np.radians(30))), rel=0.02)


# -- bad input --------------------------------------------------------------------------------
@pytest.mark.parallel
def test_bad_collider_input_is_named():
    with pytest.raises(ValueError, match=r"a collider plane needs a finite, non-zero normal with 2 components"):
        plane((0.0, 0.0), (0.0, 0.0))
    with pytest.raises(ValueError, match=r"non-zero normal with 3 components"):
        plane((0.0, 0.0, 0.0), (0.0, 0.0))
    with pytest.raises(ValueError, match=r"a collider disk needs a finite radius > 0"):
        disk((0.0, 0.0), 0.0)
    with pytest.raises(ValueError, match=r"a collider box needs lo < hi in every component"):
        box((0.0, 1.0), (1.0, 1.0))
    with pytest.raises(ValueError, match=r"enclose an area"):
        polygon([[0, 0], [1, 1], [2, 2]])
    with pytest.raises(ValueError, match=r"3 or more finite points"):
        polygon([[0, 0], [1, 1]])
    with pytest.raises(ValueError, match=r"friction coefficient mu >= 0"):
        Collider(plane((0, 0), (0, 1)), friction=-0.1)
    with pytest.raises(ValueError, match=r"velocity must be 2 finite numbers"):
        Collider(plane((0, 0), (0, 1)), velocity=(1.0, 0.0, 0.0))
    with pytest.raises(TypeError, match=r"a collider's shape needs dim, distance\(x\) and normal_at\(x\).* str lacks dim, distance, normal_at"):
        Collider("floor")
    scene = pushed_block()
    scene.colliders = [Collider(disk((0.0, 0.0, 0.0), 0.1))]
    with pytest.raises(ValueError, match=r"colliders\[0\] has a shape of dimension 3; the mesh has 2"):
        scene.solver()
    scene.colliders = [Collider(disk((0.0, 0.0), 0.1), velocity=lambda t: (np.nan, 0.0))]
    with pytest.raises(ValueError, match=r"velocity must be 2 finite numbers"):
        scene.solver().step()


# -- fast colliders -----------------------------------------------------------------------------
def test_a_collider_faster_than_the_waves_pushes_the_body_and_never_passes_it():
    """A box at 1000 m/s (100 times the block's wave speed) into the free block: the steps
    shorten so that it moves at most the CFL fraction of a cell per step, the block takes its
    impulse (momentum balance to round-off) and no particle is ever more than a quarter cell
    inside the box (before the steps honoured the colliders, one step carried the box through the
    block untouched)."""
    scene = pushed_block(speed=1000.0)
    solver = scene.solver()
    shape = scene.colliders[0].shape
    p0, p = _momentum(scene.particles), scene.particles
    h = 0.05
    steps = 0
    while solver.collisions.displacement[0][0] < 0.04 + 2 * h:  # the box face 2 cells past the block's face
        dt = solver.step()
        steps += 1
        assert 1000.0 * dt <= 0.4 * h * (1 + 1e-9)
        inside = shape.distance(p.x - solver.collisions.displacement[0]) < -0.25 * h  # measured: 0.13 cells at most
        assert not p.comm.allreduce(int(np.count_nonzero(inside)))
    assert steps >= 0.14 / (0.4 * h)
    impulse = solver.collisions.impulse[0]
    assert impulse[0] < -1.0
    assert np.abs(_momentum(p) - p0 + impulse).max() <= 1e-10 * np.abs(impulse).max()


def test_a_short_fast_stroke_moves_the_collider_its_whole_way():
    """A collider at 1000 m/s for 0.5 ms, then at rest (before, its speed was sampled at the
    middle of steps longer than the stroke: it never moved): the steps during the stroke are
    short enough, and its displacement is the stroke's 0.5 m (a step that holds the stroke's end
    integrates a jump: within a few per cent)."""
    scene = pushed_block(velocity=lambda t: np.array([1000.0 if t < 5e-4 else 0.0, 0.0]))
    scene.colliders = [Collider(box((0.0, 0.42), (0.05, 0.48)), velocity=scene.colliders[0].velocity)]
    solver = scene.solver()
    dts = []
    while solver.t < 2e-3:
        dts.append(solver.step(dt_max=2e-3 - solver.t))
    assert solver.collisions.displacement[0][0] == pytest.approx(0.5, rel=0.03)
    assert max(dts[:3]) <= 0.4 * 0.05 / 1000.0 * (1 + 1e-9)


def test_a_given_step_a_collider_would_cross_a_cell_in_is_refused():
    scene = pushed_block(speed=1000.0)
    solver = scene.solver()
    with pytest.raises(fempm.SimulationError, match="lets a collider move more than the smallest cell"):
        solver.step(1e-4)


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="starts its own process")
def test_a_fast_footing_takes_the_steps_its_speed_needs(tmp_path):
    """`run footing --cells 4 --speed 1000` (ten times the layer's wave speed; it took one step,
    exit 0, with a bearing ratio of 26591): the footing moves at most 0.4 cells a step."""
    import subprocess
    import sys

    out = tmp_path / "footing"
    r = subprocess.run([sys.executable, "-m", "fempm", "run", "footing", "--cells", "4", "--speed", "1000",
                        "--out", str(out)], capture_output=True, text=True, timeout=300)
    summary = json.loads((out / "summary.json").read_text())
    assert r.returncode in (0, 3), r.stderr
    penetration = 0.1  # m, the scene's depth 0.1 of the width 1
    assert summary["steps"] >= penetration / (0.4 * 0.25)
    with open(out / "energies.csv", newline="") as f:
        dts = [float(row["dt"]) for row in csv.DictReader(f)]
    assert max(dts) * 1000.0 <= 0.4 * 0.25 * (1 + 1e-9)
