"""The particle-grid operator: partition of unity, exact gradients of linear fields."""

import basix
import basix.ufl
import dolfinx.fem as fem
import fempm
import numpy as np
import pytest
from conftest import make_mesh


@pytest.mark.parametrize("degree", [1, 2])
def test_partition_of_unity_and_linear_gradients(mesh_name, degree):
    mesh = make_mesh(mesh_name)
    p = fempm.create_particles(mesh, 2 ** mesh.topology.dim, jitter=0.8, seed=1)
    V = fem.functionspace(mesh, ("Lagrange", degree))
    B = fempm.ParticleBasis(V, p, gradients=True)
    np.testing.assert_allclose(B.values.sum(axis=1), 1.0, atol=1e-13)
    np.testing.assert_allclose(B.gradients.sum(axis=1), 0.0, atol=1e-10)
    # sum_a x_{d(p,a)} grad N_a = I for the interpolated coordinate field (exact on affine
    # cells and for degree 2 on the mesh's own Q1/P1 geometry)
    gdim = mesh.geometry.dim
    xdofs = V.tabulate_dof_coordinates()[:, :gdim]
    grad_x = np.einsum("nag,nah->nhg", B.gradients, xdofs[B.dofs])
    np.testing.assert_allclose(grad_x, np.broadcast_to(np.eye(gdim), grad_x.shape), atol=1e-10)
    np.testing.assert_allclose(np.einsum("na,nag->ng", B.values, xdofs[B.dofs]), p.x, atol=1e-12)


def test_bernstein_basis_is_nonnegative():
    mesh = make_mesh("triangle")
    p = fempm.create_particles(mesh, 9, jitter=1.0, seed=3)
    el = basix.ufl.element("P", "triangle", 2, lagrange_variant=basix.LagrangeVariant.bernstein)
    B = fempm.ParticleBasis(fem.functionspace(mesh, el), p)
    assert B.nonnegative and B.values.min() >= 0.0
    np.testing.assert_allclose(B.values.sum(axis=1), 1.0, atol=1e-13)
    assert not fempm.ParticleBasis(fem.functionspace(mesh, ("Lagrange", 2)), p).nonnegative
