"""Patches of marked nodes (fempm.boundary.patches): the sums over each connected set of marked dofs
are the same on every rank, owned or ghost, and on any number of ranks."""

import dolfinx.fem
import dolfinx.mesh as dm
import numpy as np
import pytest
from mpi4py import MPI

import fempm  # noqa: F401  (DOLFINx from the wheel first)
from fempm.boundary.patches import Patches, components

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD


@pytest.mark.parametrize("cell", [dm.CellType.triangle, dm.CellType.quadrilateral])
def test_sums_over_two_blobs_on_any_number_of_ranks(cell):
    """On a unit square of 8 x 8 cells, the P1 dofs in x, y <= 0.25 (a blob of 3 x 3 nodes)
    and in x, y >= 0.75 less the corner (1, 1) (8 nodes, still connected) are marked. Each
    marked dof, on every rank, gets its blob's node count and sum of x: 9 and 9 * 0.125 = 1.125,
    8 and 3 * 0.75 + 3 * 0.875 + 2 * 1 = 6.875."""
    mesh = dm.create_unit_square(comm, 8, 8, cell)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    x = V.tabulate_dof_coordinates()[:, :2]
    low = np.all(x <= 0.25 + 1e-12, axis=1)
    high = np.all(x >= 0.75 - 1e-12, axis=1) & ~np.all(np.isclose(x, 1.0), axis=1)
    dofs = np.flatnonzero(low | high)
    sums = Patches.of_space(V).sums(dofs, np.stack([np.ones(len(dofs)), x[dofs, 0]], axis=1))
    expect = np.where(low[dofs, None], [9.0, 1.125], [8.0, 6.875])
    np.testing.assert_allclose(sums, expect, rtol=1e-14)
    assert comm.allreduce(len(dofs)) >= 17


def test_a_wall_patch_and_nothing_marked():
    """Restricted to the cells with two or more wall dofs (the floor y = 0): the floor nodes at
    x <= 3/8 form one patch, those at x >= 3/4 another. With nothing marked on any rank every
    call returns an empty array (collectively)."""
    mesh = dm.create_unit_square(comm, 8, 4)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    x = V.tabulate_dof_coordinates()[:, :2]
    floor = np.flatnonzero(np.isclose(x[:, 1], 0.0))
    patches = Patches.of_space(V, floor)
    marked = floor[(x[floor, 0] <= 0.375 + 1e-12) | (x[floor, 0] >= 0.75 - 1e-12)]
    sums = patches.sums(marked, np.ones((len(marked), 1)))
    np.testing.assert_array_equal(sums[:, 0], np.where(x[marked, 0] < 0.5, 4.0, 3.0))
    assert patches.sums(marked[:0], np.ones((0, 2))).shape == (0, 2)


def test_components():
    """Edges 0-1, 1-2, 4-3 among six nodes: components {0, 1, 2}, {3, 4} and {5}, each
    labelled by its smallest node."""
    np.testing.assert_array_equal(components(6, np.array([0, 1, 4]), np.array([1, 2, 3])), [0, 0, 0, 3, 3, 5])
