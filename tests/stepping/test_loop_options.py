"""Loop features for convergence studies: body forces of the reference position, tractions
with an exact total force, a fixed time step that ends exactly at t_end, particle error
norms, damping; a P2 scene with output. Serial and on 2 ranks."""

import dolfinx.fem
import dolfinx.mesh as dm
import numpy as np
import pytest
from mpi4py import MPI

import fempm
from fempm.verification import manufactured as mf
from fempm.verification.errors import ErrorHistory, particle_errors
from fempm.materials import LinearElastic
from fempm.scene import Scene, run
from fempm.scenes.manufactured import manufactured_scene
from fempm.stepping.loads import surface_areas, takes_reference_positions
from fempm.particles.seeding import create_particles
from fempm.meshes import unstructured_rectangle
from fempm.stepping import ExplicitSolver, Loads, StepOptions

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD


def _block(ppc: int, cells: int = 8):
    comm = MPI.COMM_WORLD
    mesh = dm.create_rectangle(comm, [[0.0, 0.0], [2.0, 1.0]], [2 * cells, cells], dm.CellType.quadrilateral)
    p = create_particles(mesh, ppc, density=3.0, cells=lambda x: x[0] < 1.0)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    return mesh, p, V


def _momentum(p):
    return p.comm.allreduce(p.mass @ p.fields["v"])


def test_body_force_signatures():
    assert not takes_reference_positions(lambda x, t: x)
    assert takes_reference_positions(lambda x, t, X: x)
    assert takes_reference_positions(lambda *a: a[0])
    assert not takes_reference_positions(max)  # no signature: the (x, t) form


@pytest.mark.parametrize("form", ["reference", "current"])
def test_body_force_sees_the_reference_positions(form):
    """One step from rest without stress: the momentum gained is dt sum_p M_p b(X_p) for
    b(x, t, X) = (X_0, t) (the reference positions, which differ from x) and dt sum_p M_p b(x_p)
    for the (x, t) form."""
    mesh, p, V = _block(4)
    p.fields["X0"] = p.x + 0.05  # reference positions that are not the current ones
    dt = 1e-4
    if form == "reference":
        loads = Loads(body_force=lambda x, t, X: np.column_stack([X[:, 0], np.full(len(X), t + 1.0)]))
        b = np.column_stack([p.fields["X0"][:, 0], np.ones(len(p))])
    else:
        loads = Loads(body_force=lambda x, t: np.column_stack([x[:, 1], np.zeros(len(x))]))
        b = np.column_stack([p.x[:, 1], np.zeros(len(p))])
    expected = p.comm.allreduce(p.mass @ b) * dt
    solver = ExplicitSolver(V, p, [LinearElastic(1.0, 0.0)], loads=loads, options=StepOptions(flip=1.0))
    solver.step(dt)
    assert np.allclose(_momentum(p), expected, rtol=1e-12)
    bad = ExplicitSolver(V, p, [LinearElastic(1.0, 0.0)], loads=Loads(body_force=lambda x, t: x[:, :1]))
    with pytest.raises(ValueError, match="body force returned shape"):
        bad.step(dt)


@pytest.mark.parametrize("ppc", [1, 4, 9])
def test_traction_gives_the_exact_total_force(ppc):
    """A traction t on the particle layer along x = 1 (length 1) of a block: the first step's
    momentum is t * 1 * dt at any number of particles per cell, with the default areas (square
    particles) and with surface_areas()."""
    mesh, p, V = _block(ppc)
    dt = 1e-4
    t_bar = np.array([0.3, -0.2])
    layer = p.x[:, 0] > 1.0 - 1.0 / 8 / np.sqrt(ppc)
    assert p.comm.allreduce(int(layer.sum())) == 8 * int(np.sqrt(ppc))
    for areas in (None, surface_areas(p.volume, layer, 1.0, p.comm)):
        q = p
        q.fields.pop("area", None)
        if areas is not None:
            q.fields["area"] = areas
        q.fields["v"] = np.zeros((len(q), 2))
        traction = np.where(layer[:, None], t_bar, 0.0)
        solver = ExplicitSolver(V, q, [LinearElastic(1.0, 0.0)], loads=Loads(traction=lambda t, traction=traction: traction))
        x0 = q.x.copy()
        solver.step(dt)
        assert np.allclose(_momentum(q), t_bar * dt, rtol=1e-12)
        assert solver.terms == {"internal": 1, "traction": 1}
        q.x = x0
        q.relocate()


LOADED_MESHES = {
    "triangle, right": lambda: dm.create_unit_square(comm, 8, 8, dm.CellType.triangle, diagonal=dm.DiagonalType.right),
    "triangle, crossed": lambda: dm.create_unit_square(comm, 8, 8, dm.CellType.triangle,
                                                       diagonal=dm.DiagonalType.crossed),
    "triangle, gmsh": lambda: unstructured_rectangle(comm, 1.0 / 8),
    "quadrilateral": lambda: dm.create_unit_square(comm, 8, 8, dm.CellType.quadrilateral),
    "tetrahedron": lambda: dm.create_unit_cube(comm, 4, 4, 4),
    "hexahedron": lambda: dm.create_unit_cube(comm, 4, 4, 4, dm.CellType.hexahedron),
}


@pytest.mark.parametrize("mesh_name", sorted(LOADED_MESHES))
def test_the_default_surface_share_gives_the_total_force_on_every_cell_type(mesh_name):
    """A traction t on the particles next to the face x = 1 (measure 1) with the default share
    (no fields["area"]: fempm.stepping.loads.boundary_shares): the first step's momentum is t dt, for
    the layer of the particles nearest to it and (in 2D) for layers one lattice row and one
    cell thick, at 1, 4 (8) and 9 particles per cell. Before, the share V^(1/2) of a square particle gave 0.71 or 1.41
    of the force on triangles."""
    mesh = LOADED_MESHES[mesh_name]()
    d = mesh.geometry.dim
    h = 1.0 / 8 if d == 2 else 0.25
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (d,)))
    t_bar = np.array([0.3, -0.2, 0.1][:d])
    dt = 1e-4
    for ppc in ((1, 4, 9) if d == 2 else (1, 8)):
        n = round(ppc ** (1 / d))
        # the nearest particles, one lattice row, one cell; on tetrahedra the nearest only: the
        # Kuhn sub-tetrahedra's rows are 1/4 h apart, and thicker layers wrap round the cube's edges
        bands = (0.3 * h / n,) if mesh_name == "tetrahedron" else (0.6 * h / n, h / n, h)
        for band in bands:
            p = fempm.create_particles(mesh, ppc, density=1.0)
            layer = p.x[:, 0] > 1.0 - band
            assert p.comm.allreduce(int(layer.sum())) > 0
            traction = np.where(layer[:, None], t_bar, 0.0)
            solver = ExplicitSolver(V, p, [LinearElastic(1.0, 0.0)], loads=Loads(traction=lambda t, traction=traction: traction))
            solver.step(dt)
            assert np.allclose(_momentum(p), t_bar * dt, rtol=1e-12), (ppc, band)
            assert "surface_share" in p.fields and "area" not in p.fields


def test_fixed_dt_ends_exactly_at_t_end_and_errors_are_reduced():
    """run() with a fixed dt: ceil(t_end / dt) steps, the last one shortened, t = t_end
    exactly; the recorded particle errors are the maxima over time and equal
    particle_errors() at the end."""
    problem = mf.axis_aligned_1d(1e-4)
    scene = manufactured_scene(problem, 16, dt=5e-4, t_end=0.0037)
    hist = ErrorHistory(problem, scene.particles)
    summary = run(scene, None, progress=False, callback=hist)
    assert summary["steps"] == 8 and summary["solver"].t == 0.0037
    dts = [r["dt"] for r in summary["history"][1:]]
    assert np.allclose(dts[:-1], 5e-4) and np.isclose(dts[-1], 0.0037 - 7 * 5e-4)
    assert hist.rows[-1]["t"] == 0.0037
    end = particle_errors(scene.particles, problem, 0.0037)
    assert end == {k: hist.rows[-1][k] for k in ("max", "rms", "l2")}
    assert hist.worst["max"] == max(r["max"] for r in hist.rows) > 0
    with pytest.raises(ValueError, match="dt=-1"):
        manufactured_scene(problem, 16, dt=-1.0)


def test_particle_errors_of_the_exact_motion_vanish():
    """Particles moved along the exact motion have zero error; a known offset is measured in
    every norm (max, rms, and the V0-weighted L2 norm over the body, reduced over ranks)."""
    problem = mf.generalized_vortex(1.0)
    scene = manufactured_scene(problem, 24)
    p = scene.particles
    X = p.fields["X0"]
    p.x = X + problem.displacement(X, 0.3)
    e = particle_errors(p, problem, 0.3)
    assert max(e.values()) < 1e-14
    p.x = p.x + np.array([3e-3, 4e-3])
    e = particle_errors(p, problem, 0.3)
    area = p.comm.allreduce(float(p.fields["volume0"].sum()))
    assert np.isclose(e["max"], 5e-3) and np.isclose(e["rms"], 5e-3) and np.isclose(e["l2"], 5e-3 * np.sqrt(area))
    assert abs(area - np.pi * (1.25**2 - 0.75**2)) < 0.01  # the polar lattice fills the annulus


def test_damping_leaves_statics_and_removes_kinetic_energy():
    """A vibrating bar with grid damping loses its kinetic energy (undamped: kept); a body at
    rest under no load stays at rest."""
    problem = mf.vibrating_bar()
    energy = {}
    for c in (0.0, 0.5):
        scene = manufactured_scene(problem, 16, t_end=10.0, damping=c)
        s = run(scene, None, progress=False)
        energy[c] = s["final"]["total"] / s["initial"]["total"]
    assert energy[0.0] > 0.97 and energy[0.5] < 0.02


def test_p2_scene_with_output_runs(tmp_path):
    """A P2 (consistent mass) cantilever writes its frames: the grid stress is projected with
    consistent mass (P2 Lagrange lumped masses can vanish), Bernstein P2 with lumped mass."""
    from fempm.scenes import cantilever

    out = MPI.COMM_WORLD.bcast(str(tmp_path), root=0)
    scene = cantilever(cells=2, ppc=9, degree=2, mass="consistent", t_end=2e-4, frames=2)
    s = run(scene, f"{out}/p2", progress=False)
    solver = s["solver"]
    assert solver.V.element.basix_element.degree == 2 and s["steps"] > 2
    sigma = solver.grid_stress()
    assert sigma.function_space.element.basix_element.degree == 2
    assert np.all(np.isfinite(sigma.x.array))
    if MPI.COMM_WORLD.rank == 0:
        import os

        assert os.path.isfile(f"{out}/p2/grid_stress.pvd") and os.path.isfile(f"{out}/p2/summary.json")
    tri = dm.create_unit_square(MPI.COMM_WORLD, 4, 4)
    p = create_particles(tri, 9, density=1.0)
    p.fields["sigma"] = np.broadcast_to(np.diag([2.0, -1.0]), (len(p), 2, 2)).copy()
    scene = Scene("bernstein", tri, p, [LinearElastic(1.0, 0.2)], t_end=1.0, degree=2, variant="bernstein")
    sigma = scene.solver().grid_stress()
    uniform = sigma.x.array.reshape(-1, 4)
    assert np.allclose(uniform, [2.0, 0.0, 0.0, -1.0], atol=1e-12)
