"""Conditions on tagged facets (fempm.boundary.tagged): the nodes of the tagged facets, their
normals averaged from the facets (exact on straight and inclined walls, the bisector at a
corner, the radial direction on a polygon around a circle), one normal kept where a wall is
straight (an axis-aligned one holds a component), P1 and P2, triangles and quadrilaterals,
serial = 2 ranks; the errors."""

import dolfinx.fem
import dolfinx.mesh as dm
import numpy as np
import pytest
from mpi4py import MPI

import fempm  # noqa: F401  (before dolfinx)
from fempm.boundary import Fixed, Friction, Slip, tagged
from fempm.meshes import tagged_polygon


comm = MPI.COMM_WORLD
THETA = np.radians(30.0)
SLOPE = np.array([[0.0, 0.0], [2.0 * np.cos(THETA), -2.0 * np.sin(THETA)], [2.0 * np.cos(THETA), 1.0], [0.0, 1.0]])


def _space(mesh, degree=1):
    return dolfinx.fem.functionspace(mesh, ("Lagrange", degree, (2,)))


@pytest.mark.parametrize("quadrilateral", [False, True], ids=["triangles", "quadrilaterals"])
@pytest.mark.parametrize("degree", [1, 2])
@pytest.mark.parallel(only=("1-triangles",))
def test_an_inclined_wall_slips_along_itself(degree, quadrilateral):
    data = tagged_polygon(comm, SLOPE, 0.2, [1, 2, 3, 2], quadrilateral=quadrilateral)
    V = _space(data.mesh, degree)
    floor = tagged(V, data.facet_tags, 1, "slip")
    assert isinstance(floor, Slip) and np.shape(floor.normal) == (2,)  # straight: one normal
    np.testing.assert_allclose(floor.normal, [-np.sin(THETA), -np.cos(THETA)], atol=1e-12)
    x = V.tabulate_dof_coordinates()[floor.dofs, :2]
    np.testing.assert_allclose(x @ np.array([np.sin(THETA), np.cos(THETA)]), 0.0, atol=1e-12)  # on the slope
    count = comm.allreduce(int(np.count_nonzero(floor.dofs < V.dofmap.index_map.size_local)))
    edges = comm.allreduce(len(data.facet_tags.find(1)[data.facet_tags.find(1) < data.mesh.topology.index_map(
        1).size_local]))
    assert count == edges * degree + 1  # every node of the tagged edges, once
    v = np.ones((V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts, 2))
    floor.apply(v)
    np.testing.assert_allclose(v[floor.dofs] @ floor.normal, 0.0, atol=1e-14)
    top = tagged(V, data.facet_tags, 3, "slip")  # the horizontal top: an axis-aligned wall
    assert top.axis == 1 and top.zero_components
    sides = tagged(V, data.facet_tags, 2, "slip")  # two opposite walls: a normal per node
    assert np.shape(sides.normal) == (len(sides.dofs), 2)
    np.testing.assert_allclose(np.abs(sides.normal[:, 0]), 1.0, atol=1e-12)
    corner = tagged(V, data.facet_tags, 2, "fixed")
    assert isinstance(corner, Fixed) and np.array_equal(corner.dofs, sides.dofs)


def test_normals_of_a_polygon_around_a_circle_are_radial_and_corners_bisect():
    k = 40
    a = 2 * np.pi * np.arange(k) / k
    data = tagged_polygon(comm, np.stack([np.cos(a), np.sin(a)], axis=1), 0.15, [1] * k)
    V = _space(data.mesh)
    wall = tagged(V, data.facet_tags, 1, "friction", friction=0.3)
    assert isinstance(wall, Friction) and wall.mu == 0.3
    x = V.tabulate_dof_coordinates()[wall.dofs, :2]
    radial = x / np.linalg.norm(x, axis=1)[:, None]
    cosines = np.einsum("kd,kd->k", wall.normal, radial)
    assert comm.allreduce(float(np.min(cosines, initial=1.0)), op=MPI.MIN) > np.cos(np.pi / k)  # within half a side
    polygon_corners = np.isclose(np.linalg.norm(x, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(cosines[polygon_corners], 1.0, atol=1e-12)  # the bisector of equal sides


def test_a_frictional_wall_with_a_normal_per_node_applies_coulomb():
    """mu = 0.5 on two walls of opposite normals: each node's normal velocity into its wall
    removed, the tangential one reduced by mu times it, a node leaving its wall untouched."""
    n = np.array([[1.0, 0.0], [-1.0, 0.0], [1.0, 0.0]])
    wall = Friction(np.array([0, 1, 2], dtype=np.int32), n, 0.5)
    v = np.array([[2.0, 3.0], [-1.0, 1.0], [-1.0, 1.0]])
    wall.apply(v)
    np.testing.assert_allclose(v, [[0.0, 2.0], [0.0, 0.5], [-1.0, 1.0]], atol=1e-15)


@pytest.mark.parallel
def test_two_ranks_find_the_serial_normals():
    data = tagged_polygon(comm, SLOPE, 0.2, [1, 2, 2, 2])
    V = _space(data.mesh)
    wall = tagged(V, data.facet_tags, 2, "slip")
    x = V.tabulate_dof_coordinates()[wall.dofs, :2]
    mine = {tuple(np.round(p, 9)): tuple(np.round(q, 12)) for p, q in zip(x, wall.normal)}
    alone = tagged_polygon(MPI.COMM_SELF, SLOPE, 0.2, [1, 2, 2, 2])
    Vs = _space(alone.mesh)
    serial = tagged(Vs, alone.facet_tags, 2, "slip")
    xs = Vs.tabulate_dof_coordinates()[serial.dofs, :2]
    reference = {tuple(np.round(p, 9)): tuple(np.round(q, 12)) for p, q in zip(xs, serial.normal)}
    assert all(reference[p] == q for p, q in mine.items())
    assert comm.allreduce(len(set(mine) - set(reference))) == 0


@pytest.mark.parallel
def test_bad_input_is_named():
    data = tagged_polygon(comm, SLOPE, 0.3, [1, 2, 0, 2])
    V = _space(data.mesh)
    with pytest.raises(ValueError, match=r"unknown facet tag 7: it marks no facets on any rank \(the facet tags hold "
                                         r"1, 2\)"):
        tagged(V, data.facet_tags, 7, "slip")
    with pytest.raises(ValueError, match=r"unknown kind='glued' of tagged condition"):
        tagged(V, data.facet_tags, 1, "glued")
    with pytest.raises(ValueError, match=r"friction needs a finite coefficient mu >= 0 \(got -0.1\)"):
        tagged(V, data.facet_tags, 1, "friction", friction=-0.1)
    cells = dm.meshtags(data.mesh, 2, np.arange(data.mesh.topology.index_map(2).size_local, dtype=np.int32),
                        np.ones(data.mesh.topology.index_map(2).size_local, dtype=np.int32))
    with pytest.raises(ValueError, match=r"tagged conditions and loads need facet tags \(dimension 1\)"):
        tagged(V, cells, 1, "slip")
    with pytest.raises(ValueError, match=r"edge_tags needs one tag >= 0 per edge \(4\)"):
        tagged_polygon(comm, SLOPE, 0.3, [1, 2])


@pytest.mark.parametrize("quadrilateral", [False, True], ids=["triangles", "quadrilaterals"])
@pytest.mark.parametrize("degree", [1, 2])
@pytest.mark.parallel(only=("1-triangles",))
def test_a_wall_ending_at_an_opening_leaves_its_end_free(degree, quadrilateral):
    """A hopper's walls end at the outlet's lips, where the boundary turns outward round the
    chamber below (reflex corners): slip and friction walls leave those two nodes free (a
    condition there turned the material falling past the lip along the wall, a cell into the
    outlet); the convex top corners and a fixed wall keep every node."""
    import importlib

    silo = importlib.import_module("fempm.scenes.silo")
    vertices, tags, top = silo._outline(0.1, 30.0)
    data = tagged_polygon(comm, vertices, 0.025, tags, quadrilateral=quadrilateral)
    V = _space(data.mesh, degree)
    lips = np.array([[-0.05, silo.OUTLET_HEIGHT], [0.05, silo.OUTLET_HEIGHT]])
    tops = np.array([[-0.25, top], [0.25, top]])

    def held(points, condition):
        x = V.tabulate_dof_coordinates()[condition.dofs, :2]
        found = [bool(np.any(np.linalg.norm(x - p, axis=1) < 1e-9)) for p in points]
        return [bool(v) for v in np.logical_or.reduce(comm.allgather(np.array(found)))]

    for kind in ("slip", "friction"):
        wall = tagged(V, data.facet_tags, silo.WALL_TAG, kind, 0.3)
        assert held(lips, wall) == [False, False] and held(tops, wall) == [True, True], kind
    fixed = tagged(V, data.facet_tags, silo.WALL_TAG, "fixed")
    assert held(lips, fixed) == [True, True]
    floor = tagged(V, data.facet_tags, silo.FLOOR_TAG, "slip")  # a straight run on: both ends held
    assert held(np.array([[-0.2, 0.0], [0.2, 0.0]]), floor) == [True, True]
