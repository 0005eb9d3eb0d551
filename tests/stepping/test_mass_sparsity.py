"""The kept entries of the consistent mass systems (fempm.stepping.mass_sparsity): point
particles' pairs of a cell's dofs, particle domains' pairs of dofs whose supports meet at a
vertex, the wide cells' star dofs by star dofs, and every cell's slots among them."""

import itertools

import fempm  # noqa: F401
import dolfinx.fem
import dolfinx.mesh as dm
import numpy as np
import pytest
from mpi4py import MPI

from fempm.stepping.mass_sparsity import entries


def mesh_dofs(cell):
    mesh = dm.create_unit_square(MPI.COMM_SELF, 4, 3, cell)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    return V.dofmap.list, V.dofmap.index_map.size_local


def star_dofs(cell_dofs):
    """Each cell's sorted star dofs (of the cells sharing a dof, a vertex for P1), padded with the last."""
    stars = [np.unique(cell_dofs[np.any(np.isin(cell_dofs, row), axis=1)]) for row in cell_dofs]
    S = max(len(s) for s in stars)
    return np.array([np.concatenate([s, np.full(S - len(s), s[-1])]) for s in stars], dtype=np.int32)


def check_slots(keys, slot, local, width):
    for q in range(len(local)):
        for a, b in itertools.product(range(local.shape[1]), repeat=2):
            key = local[q, a] * width + local[q, b]
            at = np.searchsorted(keys, key)
            expected = at if at < len(keys) and keys[at] == key else len(keys)
            assert slot[q, a, b] == expected


@pytest.mark.parametrize("cell", [dm.CellType.triangle, dm.CellType.quadrilateral])
def test_the_entries_of_point_particles_are_the_pairs_of_a_cells_dofs(cell):
    cell_dofs, n = mesh_dofs(cell)
    keys, slot = entries(cell_dofs, n, n)
    pairs = {(i, j) for row in cell_dofs for i in row for j in row} | {(i, i) for i in range(n)}
    assert set(zip(*divmod(keys, n))) == pairs and np.all(np.diff(keys) > 0)
    check_slots(keys, slot, cell_dofs, n)


@pytest.mark.parametrize("cell", [dm.CellType.triangle, dm.CellType.quadrilateral])
def test_the_entries_of_domains_are_the_pairs_whose_supports_meet_at_a_vertex(cell):
    cell_dofs, n = mesh_dofs(cell)
    star = star_dofs(cell_dofs)
    around = [cell_dofs[np.any(cell_dofs == v, axis=1)].ravel() for v in range(n)]  # the dofs of a vertex's cells
    meet = {(i, j) for dofs in around for i in dofs for j in dofs}
    keys, slot = entries(star, n, n, own=cell_dofs)
    assert set(zip(*divmod(keys, n))) == meet
    assert len(keys) < 0.75 * len({(i, j) for row in star for i in row for j in row})
    check_slots(keys, slot, star, n)
    wide = np.zeros(len(cell_dofs), dtype=bool)
    wide[[3, 7]] = True  # these cells keep their star dofs by star dofs
    keys, slot = entries(star, n, n, own=cell_dofs, wide=wide)
    assert set(zip(*divmod(keys, n))) == meet | {(i, j) for row in star[wide] for i in row for j in row}
    check_slots(keys, slot, star, n)
    assert np.all(slot[wide] < len(keys)) and np.any(slot[~wide] == len(keys))
