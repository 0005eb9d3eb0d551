"""The compiled kernels (fempm.kernels) against their numpy references, to round-off."""

import numpy as np
import pytest

from fempm.kernels import g2p


@pytest.fixture(params=[(1, 2), (2, 4), (2, 6), (3, 8)], ids=["interval", "quad", "P2-triangle", "hex"])
def data(request):
    d, k = request.param
    rng = np.random.default_rng(k)
    n, nd = 500, 97
    dofs = rng.integers(0, nd, size=(n, k)).astype(np.int32)
    S = rng.random((n, k))
    G = rng.standard_normal((n, k, d))
    v_new, v_old, vp = rng.standard_normal((nd, d)), rng.standard_normal((nd, d)), rng.standard_normal((n, d))
    return dofs, S, G, v_new, v_old, vp


@pytest.mark.parametrize("flip", [0.0, 0.95, 1.0])
def test_g2p_kernel_equals_reference(data, flip):
    dofs, S, G, v_new, v_old, vp = data
    ref = g2p.g2p_point_numpy(dofs, S, G, v_new, v_old, vp, flip)
    got = g2p.g2p_point_numba(dofs, S[:, ::-1][:, ::-1], G, v_new, v_old, vp, flip)  # also a strided S
    for a, b in zip(ref, got):
        assert a.shape == b.shape and np.abs(a - b).max() < 1e-13 * max(1.0, np.abs(a).max())


def test_interpolation_kernel_equals_reference(data):
    dofs, S, G, v_new, _, _ = data
    for a, b in zip(g2p.velocity_and_gradient_numpy(dofs, S, G, v_new), g2p.velocity_and_gradient_numba(dofs, S, G, v_new)):
        assert np.abs(a - b).max() < 1e-13 * max(1.0, np.abs(a).max())


def test_kernels_are_compiled():
    import fempm.kernels

    assert fempm.kernels.COMPILED, "numba is a dependency of fempm: the compiled kernels must be in use"


@pytest.mark.parametrize("d", [1, 2, 3])
def test_kinematics_and_elastic_laws_equal_their_references(d):
    from fempm.kernels import kinematics as k
    from fempm.materials import LinearElastic, NeoHookean

    rng = np.random.default_rng(d)
    n = 300
    F = np.eye(d) + 0.2 * rng.standard_normal((n, d, d))
    L = rng.standard_normal((n, d, d))
    for a, b in zip(k.deform_numpy(F, L, 0.01), k.deform_numba(F, L, 0.01)):
        assert np.abs(a - b).max() < 1e-14
    for law in (NeoHookean(7.0, 0.3), LinearElastic(7.0, 0.3)):
        ref, got = law.stress_numpy(F, L, None, 0.01, None), law.stress(F, L, None, 0.01, None)
        assert np.abs(ref - got).max() < 1e-13 * np.abs(ref).max(), type(law).__name__


def test_nodal_force_kernel_equals_reference(data):
    from fempm.kernels import p2g

    dofs, S, G, _, _, _ = data
    rng = np.random.default_rng(5)
    n, d = G.shape[0], G.shape[2]
    volume, sigma, fext = rng.random(n), rng.standard_normal((n, d, d)), rng.standard_normal((n, d))
    ref = p2g.nodal_forces_numpy(dofs, S, G, volume, sigma, fext, 97)
    got = p2g.nodal_forces_numba(dofs, S, G, volume, sigma, fext, 97)
    assert np.abs(ref - got).max() < 1e-13 * np.abs(ref).max()


@pytest.mark.parametrize("cell", ["interval", "triangle", "quadrilateral", "tetrahedron", "hexahedron"])
def test_closed_form_basis_and_pull_back_equal_basix(cell):
    """fempm.kernels.shape: degree-1 values and gradients against basix's tabulation, and the
    affine pull-back against the particles' located reference coordinates."""
    import dolfinx.fem
    import dolfinx.mesh as dm
    import fempm
    from mpi4py import MPI

    from fempm.kernels import shape

    comm = MPI.COMM_SELF
    mesh = {"interval": lambda: dm.create_unit_interval(comm, 7),
            "triangle": lambda: dm.create_unit_square(comm, 5, 4),
            "quadrilateral": lambda: dm.create_unit_square(comm, 5, 4, dm.CellType.quadrilateral),
            "tetrahedron": lambda: dm.create_unit_cube(comm, 3, 3, 2),
            "hexahedron": lambda: dm.create_unit_cube(comm, 3, 2, 2, dm.CellType.hexahedron)}[cell]()
    d = mesh.geometry.dim
    p = fempm.Particles(mesh, np.random.default_rng(0).random((300, d)) * 0.98 + 0.01, 1.0, 1.0)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (d,)))
    geo = p.locator.geometry
    assert geo.affine
    S, G, dofs = shape.affine_basis(p.cells, p.X, geo._K, np.asarray(V.dofmap.list), cell)
    tab = V.element.basix_element.tabulate(1, p.X)[..., 0]
    assert np.abs(S - tab[0]).max() < 1e-14
    assert np.abs(G - np.transpose(tab[1:], (1, 2, 0)) @ geo._K[p.cells]).max() < 1e-12
    assert np.array_equal(dofs, np.asarray(V.dofmap.list)[p.cells])
    X, inside = shape.affine_pull_back(p.cells, p.x, geo._x0, geo._K, cell in ("interval", "triangle", "tetrahedron"),
                                       1e-10)
    assert inside.all() and np.abs(X - p.X).max() < 1e-14
    X, inside = shape.affine_pull_back(p.cells, p.x + 2.0, geo._x0, geo._K, cell in ("interval", "triangle",
                                                                                     "tetrahedron"), 1e-10)
    assert not inside.any()
