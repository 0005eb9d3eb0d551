"""Coulomb friction on a grid boundary (fempm.boundary.friction): a block sliding on a rough
floor under gravity decelerates at mu g, then sticks; with mu = 0 it keeps its speed."""

import dolfinx.fem
import dolfinx.mesh as dm
import numpy as np
import pytest
from mpi4py import MPI

import fempm
from fempm.transfer.centres import NodalCentres
from fempm.boundary import friction, slip
from fempm.materials import LinearElastic
from fempm.stepping import ExplicitSolver, Loads, StepOptions


comm = MPI.COMM_WORLD
G, V0 = 10.0, 1.0


def _slide(mu: float, t_end: float):
    """(times, mean horizontal velocity) of a block on the floor y = 0, started at V0."""
    mesh = dm.create_rectangle(comm, [[0.0, 0.0], [2.0, 0.5]], [32, 8], dm.CellType.quadrilateral)
    p = fempm.create_particles(mesh, 4, density=1.0, cells=lambda x: (x[0] > 0.25) & (x[0] < 0.75) & (x[1] < 0.25))
    p.fields["v"] = np.tile([V0, 0.0], (len(p), 1))
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    floor = friction(V, lambda x: np.isclose(x[1], 0.0), (0.0, -1.0), mu)
    solver = ExplicitSolver(V, p, [LinearElastic(2.0e4, 0.3)], bcs=[floor], loads=Loads(body_force=(0.0, -G)),
                            options=StepOptions(scheme="MUSL", cfl=0.4))
    times, speeds = [], []
    while solver.t < t_end:
        solver.step()
        m = comm.allreduce(float(p.mass.sum()))
        times.append(solver.t)
        speeds.append(comm.allreduce(float(p.mass @ p.fields["v"][:, 0])) / m)
    return np.array(times), np.array(speeds)


def test_a_sliding_block_decelerates_at_mu_g_and_sticks():
    mu = 0.3
    t, v = _slide(mu, 0.5)
    sliding = (t > 0.05) & (t < 0.25)
    slope = np.polyfit(t[sliding], v[sliding], 1)[0]
    assert slope == pytest.approx(-mu * G, rel=0.03)  # measured -3.02
    assert np.abs(v[t > 0.42]).max() < 0.03  # it stopped near t = V0 / (mu g) = 1/3 and stays


def test_without_friction_the_block_keeps_its_speed():
    t, v = _slide(0.0, 0.15)
    assert np.abs(v - V0).max() < 1e-3


def test_friction_needs_a_coefficient():
    mesh = dm.create_unit_square(MPI.COMM_SELF, 2, 2)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    with pytest.raises(ValueError, match="mu >= 0"):
        friction(V, lambda x: x[1] < 1e-9, (0.0, -1.0), -0.1)
    with pytest.raises(ValueError, match="friction needs a finite, non-zero normal"):
        friction(V, lambda x: x[1] < 1e-9, (0.0, 0.0), 0.3)
    assert slip(V, lambda x: x[1] < 1e-9, (0.0, 2.0)).normal[1] == 1.0
    with pytest.raises(ValueError, match="gap > 0"):
        friction(V, lambda x: x[1] < 1e-9, (0.0, -1.0), 0.3, gap=0.0)


def test_a_wall_with_a_gap_holds_only_the_nodes_the_body_touches():
    """Floor y = 0 of a 4 x 4 unit square (h = 1/4), mu = 0.5, gap 0.1: the body moves at
    (1, -0.4) everywhere. Nodal centres of mass 0.05, 0.15, 0.05, 0.0999 above the floor and
    none at x = 0, 1/4, 1/2, 3/4, 1: the nodes at 0, 1/2 and 3/4 touch it (a tangential offset
    of the centre does not count), in two patches. Each patch's wall takes the normal momentum
    of its nodes, shared by mass times depth: the single node at 0 stops (its tangential speed
    cut by mu 0.4); at 1/2 (mass 2, depth 0.05) and 3/4 (mass 1, depth 1e-4) the momentum
    1.2 goes almost all to 1/2, which leaves the wall, with friction mu times each node's share.
    The other nodes keep their velocity; without the gap every node is held. The wall needs the
    centres of mass once it has a gap."""
    mesh = dm.create_unit_square(MPI.COMM_SELF, 4, 4, dm.CellType.quadrilateral)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    wall = friction(V, lambda x: np.isclose(x[1], 0.0), (0.0, -1.0), 0.5, gap=0.1)
    assert wall.needs_positions and len(wall.dofs) == 5 and np.allclose(wall.points[:, 1], 0.0)
    at = np.rint(wall.points[:, 0] * 4).astype(int)  # each wall dof's position along the floor
    n = V.dofmap.index_map.size_local
    centre, mass = np.full((n, 2), np.nan), np.ones(n)
    centre[wall.dofs] = np.column_stack([wall.points[:, 0] + 0.3, np.array([0.05, 0.15, 0.05, 0.0999, np.nan])[at]])
    mass[wall.dofs] = np.array([1.0, 1.0, 2.0, 1.0, 0.0])[at]
    v = np.tile([1.0, -0.4], (n, 1))
    wall.apply(v, NodalCentres(centre, mass))
    got = np.empty((5, 2))
    got[at] = v[wall.dofs]
    share = 1.2 * np.array([0.05, 1e-4]) / (2 * 0.05 + 1e-4)  # the normal velocity each node gives up
    expected = [[0.8, 0.0], [1.0, -0.4], [1.0 - 0.5 * share[0], share[0] - 0.4], [1.0 - 0.5 * share[1], share[1] - 0.4],
                [1.0, -0.4]]
    np.testing.assert_allclose(got, expected, rtol=1e-14)
    normal = np.array([2.0, 1.0]) @ (got[2:4, 1] - (-0.4))  # the momentum the patch took, normal and tangential
    tangential = np.array([2.0, 1.0]) @ (1.0 - got[2:4, 0])
    assert abs(normal - 1.2) < 1e-14 and abs(tangential - 0.5 * 1.2) < 1e-14
    v = np.tile([1.0, 0.4], (n, 1))  # leaving the floor everywhere: nothing held
    wall.apply(v, NodalCentres(centre, mass))
    np.testing.assert_array_equal(v, np.tile([1.0, 0.4], (n, 1)))
    plain = friction(V, lambda x: np.isclose(x[1], 0.0), (0.0, -1.0), 0.5)
    v = np.tile([1.0, -0.4], (n, 1))
    plain.apply(v)
    np.testing.assert_allclose(v[plain.dofs], [[0.8, 0.0]] * 5, rtol=1e-15)
    with pytest.raises(ValueError, match="nodal centres of mass"):
        wall.apply(v)


@pytest.mark.parallel
def test_a_wall_shares_its_normal_momentum_per_patch_over_ranks():
    """The floor of an 8 x 8 unit square distributed over the ranks, gap 0.1: the nodes at
    x <= 1/2 and at x = 1 touch it (two patches), those between do not. Every wall node,
    owned or ghost, on every rank gives up the share of its patch's normal momentum that its
    mass times depth sets, as computed here from the whole floor."""
    mesh = dm.create_unit_square(comm, 8, 8, dm.CellType.quadrilateral)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    wall = friction(V, lambda x: np.isclose(x[1], 0.0), (0.0, -1.0), 0.3, gap=0.1)
    n = V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts

    def height(x):
        return np.where((x <= 0.5 + 1e-9) | (x >= 1.0 - 1e-9), 0.02 + 0.05 * x**2, 0.2)

    xs = V.tabulate_dof_coordinates()[:, 0]
    centre = np.column_stack([xs, height(xs)])
    mass = 1.0 + xs
    v = np.tile([0.5, -0.4], (n, 1))
    wall.apply(v, NodalCentres(centre, mass))
    floor = np.arange(9) / 8.0
    depth = 0.1 - height(floor)
    m = 1.0 + floor
    dvn = np.zeros(9)
    for patch in (floor <= 0.5, floor >= 1.0):
        dvn[patch] = (m[patch] @ np.full(patch.sum(), 0.4)) * depth[patch] / (m[patch] @ depth[patch])
    at = np.rint(xs[wall.dofs] * 8).astype(int)
    got = v[wall.dofs]
    np.testing.assert_allclose(got[:, 1], -0.4 + dvn[at], rtol=0, atol=1e-14)
    np.testing.assert_allclose(got[:, 0], 0.5 * np.maximum(0.0, 1.0 - 0.3 * dvn[at] / 0.5), rtol=0, atol=1e-14)
    assert comm.allreduce(len(wall.dofs)) >= 9 and dvn[5:8].max() == 0.0 and dvn[8] > 0
