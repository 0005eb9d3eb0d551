"""The compiled F-bar passes (fempm.kernels.fbar) against their numpy reference, FBar.rate and
patch_average of fempm.stepping.fbar on the particle basis: the averaged deformation, volume and
stress of both measures (det F and tr F bodies) and the nodal pressure averages, on every cell
type (the G2P pass that takes the average on fempm.kernels.lumped.PLANAR's cells:
tests/stepping/test_fbar_compiled.py)."""

import dolfinx.fem
import dolfinx.mesh as dm
import numpy as np
import pytest
from mpi4py import MPI

import fempm
from fempm.kernels import fbar as kb
from fempm.kernels.bundles import Basis, Laws, State
from fempm.kernels.lumped import PLANAR
from fempm.kernels.patch import BLOCK_ROWS, BLOCK_SHIFT, averages, blocks, clear_blocks
from fempm.kernels.particle_checks import LINEAR_ELASTIC, NEO_HOOKEAN
from fempm.materials import LinearElastic, NeoHookean
from fempm.stepping.fbar import FBar, patch_average, trace_measure
from fempm.transfer.basis import ParticleBasis

comm = MPI.COMM_SELF

MESHES = {
    "interval": lambda: dm.create_unit_interval(comm, 9),
    "triangle": lambda: dm.create_unit_square(comm, 5, 4),
    "quadrilateral": lambda: dm.create_unit_square(comm, 5, 4, dm.CellType.quadrilateral),
    "tetrahedron": lambda: dm.create_unit_cube(comm, 3, 3, 2),
    "hexahedron": lambda: dm.create_unit_cube(comm, 3, 2, 3, dm.CellType.hexahedron),
}


DEFAULT = (("triangle", True), ("hexahedron", False), ("interval", True))  # the rest: make test-all


@pytest.mark.parametrize(("cell", "keep_L"), [pytest.param(cell, keep_L, marks=() if (cell, keep_L) in DEFAULT
                                                           else pytest.mark.slow)
                                              for cell in MESHES for keep_L in (True, False)])
def test_compiled_fbar_passes_equal_the_numpy_average(cell, keep_L):
    mesh = MESHES[cell]()
    d = mesh.geometry.dim
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (d,)))
    p = fempm.create_particles(mesh, 2**d, jitter=0.3, seed=4)
    n = len(p)
    rng = np.random.default_rng(1)
    body = (p.x[:, 0] > 0.5).astype(np.int32)
    materials = [NeoHookean(10.0, 0.3), LinearElastic(8.0, 0.25)]
    F0 = np.eye(d) + 0.05 * rng.standard_normal((n, d, d))
    v_nodal = 0.3 * rng.standard_normal((V.dofmap.index_map.size_local, d))
    dt = 0.05
    basis = ParticleBasis(V, p, gradients=True)
    L = np.einsum("paj,pae->pje", v_nodal[basis.dofs], basis.gradients)
    # numpy reference: F-bar = (I + dt L-bar) F, the laws' stresses
    L_bar = FBar().rate(basis, p.volume, body, materials, F0, L, dt)
    F_ref = (np.eye(d) + dt * L_bar) @ F0
    by_trace = trace_measure(materials)
    # the compiled passes (the kernels' cell names are the meshes' here: affine cells, degree 1)
    name = cell
    _, K = p.locator.geometry.kernel_geometry
    where = Basis(p.cells, p.X, K, np.ascontiguousarray(V.dofmap.list, dtype=np.int32))
    patch, dirty = np.zeros((len(v_nodal), 4)), np.zeros(blocks(len(v_nodal)), dtype=np.uint8)
    Lc, value = np.full((n, d, d), np.nan), np.full(n, np.nan)
    F = F0.copy()
    kb.measure_kernel(name)(where, v_nodal, F, p.volume, body, by_trace, dt, Lc, value, patch, dirty)
    if cell in PLANAR:  # the G2P pass computes L_p and the measure again: the measure pass keeps neither
        assert np.isnan(Lc).all() and np.isnan(value).all()
        Lc = L.copy()  # (the deform pass, as on the other cells)
        value = np.where(by_trace[body], dt * np.einsum("pje,pej->p", L, F0), np.linalg.det(np.eye(d) + dt * L))
    np.testing.assert_allclose(Lc, L, rtol=0, atol=1e-13)
    assert dirty[np.flatnonzero(patch.any(axis=1)) >> BLOCK_SHIFT].all()  # every row written is in a marked block
    averages(patch, dirty)
    volume0 = p.volume.copy()
    volume, sigma = np.empty(n), np.zeros((n, d, d))
    laws = Laws(np.array([NEO_HOOKEAN, LINEAR_ELASTIC]), np.array([m.lame[0] for m in materials]),
                np.array([m.lame[1] for m in materials]), np.zeros(2))
    state = State(p.x, np.zeros((n, d)), F, volume0, volume, sigma, body, p.mass)
    counts = kb.deform_kernel(name, keep_L)(where, patch, by_trace, dt, Lc, value, state, laws)
    assert counts[:2] == (0, 0)
    np.testing.assert_allclose(F, F_ref, rtol=0, atol=1e-13)
    np.testing.assert_allclose(Lc, L_bar if keep_L else L, rtol=0, atol=1e-11)  # L-bar for the laws of their own
    np.testing.assert_allclose(volume, np.linalg.det(F_ref) * volume0, rtol=1e-13)
    for b, mat in enumerate(materials):
        idx = body == b
        np.testing.assert_allclose(sigma[idx], mat.stress(F_ref[idx], L_bar[idx], np.zeros((idx.sum(), d, d)), dt,
                                                          np.ones(idx.sum())), rtol=0, atol=1e-12)
    # the pressures' nodal averages, read at the particles
    sigma = rng.standard_normal((n, d, d))
    patch.fill(0.0)
    kb.pressure_kernel(name)(where, p.volume, sigma, body, patch, dirty)
    averages(patch, dirty)
    reference = patch_average(basis, p.volume, body, 2, np.trace(sigma, axis1=1, axis2=2) / d)
    got = np.einsum("pa,pa->p", basis.values, patch[basis.dofs, 2 + body[:, None]])
    np.testing.assert_allclose(got, reference, rtol=0, atol=1e-13)


def test_the_dirty_blocks_clear_and_average_every_row_written():
    """averages and clear_blocks visit the marked blocks only: the same averages as over every
    row, every written row zeroed, the marks reset to the blocks a ghost exchange writes."""
    rng = np.random.default_rng(3)
    rows = 5 * BLOCK_ROWS + 3  # a last block cut short
    patch, dirty = np.zeros((rows, 4)), np.zeros(blocks(rows), dtype=np.uint8)
    written = rng.choice(rows, 20, replace=False)
    written[0] = rows - 1
    patch[written] = rng.uniform(0.5, 1.0, (20, 4))
    patch[written[1], 0] = 0.0  # a row of no weight for body 0: its average is 0
    dirty[written >> BLOCK_SHIFT] = 1
    full = patch.copy()
    full[:, 2:] = np.where(full[:, :2] > 0, full[:, 2:] / np.where(full[:, :2] > 0, full[:, :2], 1.0), 0.0)
    averages(patch, dirty)
    np.testing.assert_array_equal(patch, full)
    always = np.zeros_like(dirty)
    always[-1] = 1
    clear_blocks(patch, dirty, always)
    assert not patch.any()
    np.testing.assert_array_equal(dirty, always)
