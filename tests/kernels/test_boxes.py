"""Exact GIMP as samples (fempm.kernels.boxes) against the box integrals of
fempm.transfer.box_average, their reference: the averaged basis and its gradient per (box, dof)
to round-off, on every cell type it serves, with boxes inside the mesh, straddling cells and
beyond the boundary (cut off)."""

import dolfinx
import numpy as np
import pytest
from conftest import make_mesh
from mpi4py import MPI

from fempm.kernels.boxes import box_samples
from fempm.meshes.geometry import CellGeometry
from fempm.particles.cell_bins import CellBins
from fempm.particles.location import CellLocator
from fempm.transfer.box_average import BoxIntegrator

SERVED = ["interval", "triangle", "quadrilateral", "tetrahedron", "hexahedron", "unstructured-triangle",
          "unstructured-tetrahedron"]


def averages_from_samples(V, geo, sc, Y, w):
    """Dense <N_i>_p (n, dofs) and <grad N_i>_p (n, dofs, d) from the samples."""
    n, Q = sc.shape
    d = geo.gdim
    tab = V.element.basix_element.tabulate(1, Y)[..., 0]  # (1 + d, n Q, k)
    cells = sc.ravel()
    K = geo.K[cells]  # (n Q, d, d)
    grads = np.einsum("tqa,qte->qae", tab[1:], K)
    dofs = V.dofmap.list[cells]  # (n Q, k)
    rows = np.repeat(np.arange(n), Q)[:, None] * np.ones(dofs.shape[1], dtype=int)
    nd = V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts
    A, G = np.zeros((n, nd)), np.zeros((n, nd, d))
    np.add.at(A, (rows, dofs), w.ravel()[:, None] * tab[0])
    np.add.at(G, (rows, dofs), w.ravel()[:, None, None] * grads)
    return A, G


def averages_from_integrals(V, integ, lo, hi):
    r = integ.integrals(lo, hi, True)
    n, d = lo.shape
    nd = V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts
    A, G = np.zeros((n, nd)), np.zeros((n, nd, d))
    np.add.at(A, (r.box, r.dofs), r.N / r.volume[r.box])
    np.add.at(G, (r.box, r.dofs), r.dN / r.volume[r.box][:, None])
    return A, G


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n == "unstructured-tetrahedron" else n
                                  for n in SERVED])  # (its numpy reference takes 25 s: make test-all)
def test_box_samples_equal_the_box_integrals(name):
    mesh = make_mesh(name, MPI.COMM_SELF)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    geo = CellGeometry(mesh)
    assert geo.affine
    d = geo.gdim
    loc = CellLocator(mesh)
    all_cells = np.arange(len(geo.dofmap), dtype=np.int32)
    integ = BoxIntegrator(geo, V.element.basix_element, V.dofmap.list, CellBins(geo, all_cells))
    lo_mesh, hi_mesh = geo.x.min(axis=0), geo.x.max(axis=0)
    rng = np.random.default_rng(3)
    n = 300
    x = lo_mesh + rng.uniform(0.0, 1.0, (n, d)) * (hi_mesh - lo_mesh)
    cells, _ = loc.locate(x)
    x, cells = x[cells >= 0], cells[cells >= 0]  # (the hole of the plate)
    n = len(x)
    size = (hi_mesh - lo_mesh).max()
    ell = rng.uniform(0.005, 0.12, (n, d)) * size  # many reach over cells, some beyond the mesh
    verts = np.ascontiguousarray(geo.x[geo.dofmap[:, : d + 1]])
    nodes = geo.x[geo.dofmap]
    blo, bhi = np.ascontiguousarray(nodes.min(axis=1)), np.ascontiguousarray(nodes.max(axis=1))
    simplex = name.split("-")[-1] in ("interval", "triangle", "tetrahedron")
    Q = 1
    while True:
        out = (np.empty((n, Q), np.int32), np.empty((n * Q, d)), np.empty((n, Q)))
        needed, reaching, failed = box_samples(x, ell, cells, (d, simplex), verts, (blo, bhi), loc.vertex_star(),
                                               np.zeros(len(all_cells), bool), geo.x0, geo.K, out)
        if needed <= Q:
            break
        Q = needed
    assert Q > 1 and reaching == 0 and failed == 0
    sc, Y, w = out
    assert np.allclose(w.sum(axis=1), 1.0, rtol=0, atol=1e-14)
    A, G = averages_from_samples(V, geo, sc, Y, w)
    A_ref, G_ref = averages_from_integrals(V, integ, x - ell, x + ell)
    assert np.abs(A - A_ref).max() <= 1e-13
    assert np.abs(G - G_ref).max() <= 1e-12 * np.abs(G_ref).max()

    # moved a little: the pieces found from the last samples' cells are the flood's, bit for bit
    x_moved = x + rng.uniform(-0.01, 0.01, x.shape) * size
    moved_cells, _ = loc.locate(x_moved)
    keep = moved_cells >= 0
    got = []
    for guessed in (True, False):
        arrays = tuple(a[keep].copy() if a.ndim == 2 and len(a) == n else a.reshape(n, Q, d)[keep].reshape(-1, d).copy()
                       for a in out)
        needed, _, _ = box_samples(x_moved[keep], ell[keep], moved_cells[keep], (d, simplex), verts, (blo, bhi),
                                   loc.vertex_star(), np.zeros(len(all_cells), bool), geo.x0, geo.K, arrays, guessed)
        assert needed <= Q
        got.append(arrays)
    for a, b in zip(*got):
        assert np.array_equal(a, b)
