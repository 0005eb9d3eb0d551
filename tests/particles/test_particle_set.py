"""Particles from arrays (collective distribution), location edge cases, outside-mesh errors."""

import fempm
import numpy as np
import pytest
from conftest import make_mesh
from mpi4py import MPI

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD


def _points_on_rank0(n, gdim, seed=0, lo=0.0, hi=1.0):
    rng = np.random.default_rng(seed)
    x = lo + (hi - lo) * rng.random((n, gdim))
    return x if comm.rank == 0 else np.zeros((0, gdim))


@pytest.mark.parametrize("name", ["interval", "triangle", "distorted-quadrilateral", "tetrahedron", "distorted-hexahedron"])
def test_particles_from_any_rank_end_on_owner(name):
    mesh = make_mesh(name)
    gdim = mesh.geometry.dim
    n = 400
    # rank 0 gives the first half of the points, the last rank the second half
    rng = np.random.default_rng(5)
    x_all = rng.random((n, gdim))
    ids_all = np.arange(n)
    mine = slice(0, n // 2) if comm.rank == 0 else slice(0, 0)
    if comm.rank == comm.size - 1:
        mine = slice(0, n) if comm.size == 1 else slice(n // 2, n)
    p = fempm.Particles(mesh, x_all[mine], 1.0, 0.5, ids=ids_all[mine], fields={"tag": 10 * ids_all[mine]})
    assert p.num_global == n
    assert sorted(np.concatenate(comm.allgather(p.ids)).tolist()) == list(range(n))
    np.testing.assert_allclose(p.x, x_all[p.ids])
    np.testing.assert_array_equal(p.fields["tag"], 10 * p.ids)
    geom = p.locator.geometry
    assert np.all((p.cells >= 0) & (p.cells < geom.num_owned))  # owned cells only
    np.testing.assert_allclose(geom.push_forward(p.cells, p.X), p.x, atol=1e-11)


def test_points_on_vertices_and_faces_are_found_once():
    """Mesh vertices and facet midpoints lie in several cells: each particle is counted once."""
    mesh = make_mesh("triangle")
    xg = mesh.geometry.x[:, :2]
    pts = np.unique(np.round(np.concatenate(comm.allgather(xg)), 14), axis=0)
    p = fempm.Particles(mesh, pts if comm.rank == 0 else np.zeros((0, 2)), 1.0, 1.0)
    assert p.num_global == len(pts)
    assert comm.allreduce(p.mass.sum()) == pytest.approx(len(pts))


def test_outside_particles_raise_with_count_and_position():
    mesh = make_mesh("triangle")
    x = np.array([[0.5, 0.5], [1.5, 0.2], [0.3, -0.25]])
    with pytest.raises(fempm.OutsideMeshError, match=r"2 particle\(s\) lie outside the mesh.*1\.5, 0\.2"):
        fempm.Particles(mesh, x if comm.rank == 0 else np.zeros((0, 2)), 1.0, 1.0)


def test_outside_particles_removed_on_request():
    mesh = make_mesh("unstructured-triangle")  # plate with a hole of radius 0.2 at (0.5, 0.5)
    x = np.array([[0.5, 0.5], [0.1, 0.1], [0.55, 0.45], [0.9, 0.9]])
    p = fempm.Particles(mesh, x if comm.rank == 0 else np.zeros((0, 2)), 1.0, 1.0, outside="remove")
    assert p.removed == 2 and p.num_global == 2
    with pytest.raises(ValueError, match="unknown option outside='drop'"):
        fempm.Particles(mesh, x, 1.0, 1.0, outside="drop")


@pytest.mark.parametrize("bad", ["mass", "volume"])
def test_non_positive_mass_or_volume_is_rejected(bad):
    mesh = make_mesh("triangle")
    x = np.array([[0.2, 0.2], [0.6, 0.3]])
    m = np.array([1.0, 0.0 if bad == "mass" else 1.0])
    v = np.array([1.0, -1.0 if bad == "volume" else 1.0])
    with pytest.raises(ValueError, match=f"non-positive or non-finite {bad}"):
        fempm.Particles(mesh, x, m, v)


def test_non_finite_positions_are_rejected():
    mesh = make_mesh("triangle")
    with pytest.raises(ValueError, match="not finite"):
        fempm.Particles(mesh, np.array([[np.nan, 0.2]]), 1.0, 1.0)


@pytest.mark.parametrize("name", ["triangle", "distorted-quadrilateral", "tetrahedron"])
def test_relocate_moves_particles_between_cells_and_ranks(name):
    mesh = make_mesh(name)
    p = fempm.create_particles(mesh, 2 ** mesh.topology.dim, jitter=0.5, seed=2)
    n0 = p.num_global
    ids0 = np.sort(np.concatenate(comm.allgather(p.ids)))
    # a rigid shift pattern that keeps everything inside: x -> 0.5 + 0.8 (x - 0.5), reflected
    p.x = 1.0 - p.x
    p.relocate()
    assert p.num_global == n0
    np.testing.assert_array_equal(np.sort(np.concatenate(comm.allgather(p.ids))), ids0)
    geom = p.locator.geometry
    np.testing.assert_allclose(geom.push_forward(p.cells, p.X), p.x, atol=1e-11)
    p.x[:1] += 5.0
    any_left = comm.allreduce(len(p) > 0)
    if any_left:
        with pytest.raises(fempm.OutsideMeshError):
            p.relocate()


@pytest.mark.parametrize("name", ["interval", "triangle", "quadrilateral", "tetrahedron", "hexahedron"])
def test_particles_moving_to_neighbouring_cells_are_found_without_the_tree(name):
    """A small motion: every particle that leaves its cell is found in the cells sharing a
    vertex with it (CellLocator.locate_near), in the cell and at the reference point the tree
    search finds; the tree, freed after the particles were placed, is not rebuilt: on several
    ranks the particles that move into another rank's cell find it among the ghost cells and
    go straight to its owner."""
    mesh = make_mesh(name)
    p = fempm.create_particles(mesh, 2 ** mesh.topology.dim, jitter=0.5, seed=2)
    n0 = p.num_global
    ids0 = np.sort(np.concatenate(comm.allgather(p.ids)))
    p.locator.release_tree()
    from fempm.stepping import cell_sizes

    h = cell_sizes(mesh)[p.cells]
    rng = np.random.default_rng(comm.rank)
    shift = 0.3 * h[:, None] * rng.uniform(-1.0, 1.0, p.x.shape)
    p.x = np.clip(p.x + shift, 1e-9, 1.0 - 1e-9)
    geom = p.locator.geometry
    left = ~geom.contains(geom.pull_back(p.cells, p.x), 1e-10)
    assert comm.allreduce(int(np.count_nonzero(left))) > 0  # some did leave their cells
    if comm.size > 1:  # how many move to another rank's cell
        owners = np.asarray(mesh.topology.index_map(mesh.topology.dim).owners)
        cells, _ = p.locator.locate_near(p.x[left], p.cells[left], ghosts=True)
        crossing = comm.allreduce(int(np.count_nonzero(cells >= geom.num_owned)))
        assert np.all(np.isin(owners[cells[cells >= geom.num_owned] - geom.num_owned], np.arange(comm.size)))
        assert crossing > 0 or mesh.topology.dim == 1  # one rank boundary point in 1D: maybe none cross
    p.relocate()
    assert p.locator._tree is None
    assert p.num_global == n0
    np.testing.assert_array_equal(np.sort(np.concatenate(comm.allgather(p.ids))), ids0)
    assert np.all((p.cells >= 0) & (p.cells < geom.num_owned))
    cells, X = p.locator.locate(p.x)  # the tree search, for reference
    same = cells == p.cells
    assert np.count_nonzero(~same) <= 0.01 * len(same)
    np.testing.assert_allclose(X[same], p.X[same], rtol=0.0, atol=1e-14)
    # elsewhere a point on a face shared by both cells
    assert np.all(geom.contains(geom.pull_back(p.cells[~same], p.x[~same]), 1e-9))
    np.testing.assert_allclose(geom.push_forward(p.cells, p.X), p.x, atol=1e-12)
