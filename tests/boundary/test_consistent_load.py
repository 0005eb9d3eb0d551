"""The consistent-load weights (fempm.boundary.consistent_load): the particles' weighted basis
values are the finite element's boundary integrals of the basis, on every cell type, P1 and P2,
on 1 and 2 ranks; the weights sum to the facets' measure; too few particles is an error."""

import basix
import dolfinx.fem
import dolfinx.la
import dolfinx.mesh as dm
import numpy as np
import pytest
import ufl
from conftest import make_mesh, ppc_for
from mpi4py import MPI

import fempm
from fempm.boundary.consistent_load import consistent_weights

CASES = [("triangle", 1), ("triangle", 2), ("quadrilateral", 1), ("quadrilateral", 2), ("tetrahedron", 1),
         ("hexahedron", 1), ("distorted-quadrilateral", 1), ("unstructured-triangle", 1)]


def _right_side(x):
    return np.isclose(x[0], 1.0)


def _all(x):
    return np.full(x.shape[1], True)


def _particle_vector(V, p, w, element):
    """sum_p w_p N_i(X_p), assembled over the ranks (owned dofs)."""
    b = dolfinx.la.vector(V.dofmap.index_map)
    phi = element.tabulate(0, p.X[:, : p.mesh.topology.dim])[0, :, :, 0]
    dofs = V.dofmap.list[p.cells]
    np.add.at(b.array, dofs.ravel(), (w[:, None] * phi).ravel())
    b.scatter_reverse(dolfinx.la.InsertMode.add)
    return b.array[: V.dofmap.index_map.size_local]


@pytest.mark.parametrize("name, degree", CASES, ids=[f"{n}-P{k}" for n, k in CASES])
@pytest.mark.parallel(only=("triangle-P1", "hexahedron-P1"))
def test_the_weighted_basis_values_are_the_boundary_integrals(name, degree):
    mesh = make_mesh(name)
    where = _all if name.startswith("unstructured") else _right_side
    fdim = mesh.topology.dim - 1
    facets = dm.locate_entities_boundary(mesh, fdim, where)
    p = fempm.create_particles(mesh, ppc_for(mesh, degree))
    element = basix.create_element(basix.ElementFamily.P, getattr(basix.CellType, mesh.topology.cell_type.name), degree,
                                   basix.LagrangeVariant.gll_warped)
    w = consistent_weights(p, facets, element)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", degree))
    tags = dm.meshtags(mesh, fdim, facets, np.ones(len(facets), dtype=np.int32))
    v = ufl.TestFunction(V)
    fe = dolfinx.fem.assemble_vector(dolfinx.fem.form(v * ufl.Measure("ds", domain=mesh, subdomain_data=tags)(1)))
    fe.scatter_reverse(dolfinx.la.InsertMode.add)
    fe = fe.array[: V.dofmap.index_map.size_local]
    mine = _particle_vector(V, p, w, element)
    assert np.abs(mine - fe).max() < 1e-12 * max(1.0, np.abs(fe).max())
    measure = mesh.comm.allreduce(float(fe.sum()))
    assert mesh.comm.allreduce(float(w.sum())) == pytest.approx(measure, rel=1e-12) and measure > 0.5
    # the particles of unloaded cells carry nothing
    loaded_cells = np.unique(dm.compute_incident_entities(mesh.topology, facets, fdim, fdim + 1))
    assert np.all(w[~np.isin(p.cells, loaded_cells)] == 0.0)


def test_fewer_particles_than_basis_functions_is_an_error():
    mesh = dm.create_unit_square(MPI.COMM_SELF, 4, 4)
    p = fempm.create_particles(mesh, 1)
    element = basix.create_element(basix.ElementFamily.P, basix.CellType.triangle, 1)
    facets = dm.locate_entities_boundary(mesh, 1, _right_side)
    with pytest.raises(ValueError, match="holds 1 particle"):
        consistent_weights(p, facets, element)


def test_an_interior_facet_is_an_error():
    mesh = dm.create_unit_square(MPI.COMM_SELF, 4, 4)
    p = fempm.create_particles(mesh, 4)
    element = basix.create_element(basix.ElementFamily.P, basix.CellType.triangle, 1)
    facets = dm.locate_entities(mesh, 1, lambda x: np.isclose(x[0], 0.5))
    with pytest.raises(ValueError, match="cells beside it"):
        consistent_weights(p, facets, element)
