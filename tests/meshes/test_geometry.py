import fempm
import numpy as np
import pytest
from conftest import make_mesh


@pytest.mark.parametrize("name", ["triangle", "tetrahedron", "distorted-quadrilateral", "distorted-hexahedron", "unstructured-quadrilateral"])
def test_pull_back_inverts_push_forward(name):
    mesh = make_mesh(name)
    loc = fempm.CellLocator(mesh)
    geom = loc.geometry
    rng = np.random.default_rng(1)
    n = 500
    cells = rng.integers(0, geom.num_owned, n).astype(np.int32)
    X = rng.random((n, geom.tdim))
    if geom.cell_name in ("triangle", "tetrahedron"):
        X /= X.sum(axis=1, keepdims=True) + rng.random((n, 1))
    x = geom.push_forward(cells, X)
    np.testing.assert_allclose(geom.pull_back(cells, x), X, atol=1e-11)
    # the Jacobian is the derivative of the push-forward
    eps = 1e-6
    J = geom.jacobian(cells, X)
    for t in range(geom.tdim):
        dX = np.zeros_like(X)
        dX[:, t] = eps
        fd = (geom.push_forward(cells, X + dX) - geom.push_forward(cells, X - dX)) / (2 * eps)
        np.testing.assert_allclose(J[:, :, t], fd, atol=1e-8)


def test_cell_volumes_sum_to_domain():
    for name, vol in [("distorted-hexahedron", 1.0), ("unstructured-triangle", 1 - np.pi * 0.2**2)]:
        mesh = make_mesh(name)
        geom = fempm.CellLocator(mesh).geometry
        total = mesh.comm.allreduce(geom.cell_volumes()[: geom.num_owned].sum())
        # the plate's hole is a polygon: its area approaches pi r^2 from below
        assert total == pytest.approx(vol, rel=1e-12 if name.startswith("distorted") else 3e-3)
