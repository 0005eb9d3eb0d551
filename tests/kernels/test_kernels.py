"""The compiled kernels (fempm.kernels) against their numpy references, to round-off."""

import numpy as np
import pytest

from fempm.kernels import g2p
from fempm.kernels.bundles import Basis, Forces, GridStep, Groups, Laws, Moves, Outputs, Stable, Star, State


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
    for nodal in (v_new, v_new[:, :1], np.hstack([v_new, v_new[:, ::-1]])):  # any number of components
        a, b = g2p.interpolate_numpy(dofs, S, nodal), g2p.interpolate_numba(dofs, S[:, ::-1][:, ::-1], nodal)
        assert a.shape == b.shape == (len(S), nodal.shape[1]) and np.abs(a - b).max() < 1e-13 * np.abs(a).max()
    ints = g2p.interpolate_numba(dofs, S, np.arange(len(v_new))[:, None])  # an integer field: numpy's reference
    assert np.array_equal(ints, g2p.interpolate_numpy(dofs, S, np.arange(len(v_new))[:, None]))


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
    for code in (k.NEO_HOOKEAN, k.LINEAR_ELASTIC):  # the stored energies
        ref, got = k.elastic_energy_numpy(code, F, 7.0, 0.3), k.elastic_energy_numba(code, F, 7.0, 0.3)
        assert ref.shape == (n,) and np.abs(ref - got).max() < 1e-13 * np.abs(ref).max(), code


def test_scatter_kernels_equal_their_references(data):
    from fempm.kernels import p2g

    dofs, S, G, _, _, _ = data
    rng = np.random.default_rng(6)
    n, d = G.shape[0], G.shape[2]
    w, W = rng.standard_normal((n, 3)), rng.standard_normal((n, 4, d))  # widths compiled in, read at run time
    w5, W2 = rng.standard_normal((n, 5)), rng.standard_normal((n, 2, d))  # and the other way round
    for ref, got in [(p2g.scatter_weighted_numpy(dofs, S, w, 97), p2g.scatter_weighted_numba(dofs, S, w, 97)),
                     (p2g.scatter_weighted_numpy(dofs, S, w5, 97), p2g.scatter_weighted_numba(dofs, S, w5, 97)),
                     (p2g.scatter_gradients_numpy(dofs, G, W2, 97), p2g.scatter_gradients_numba(dofs, G, W2, 97)),
                     (p2g.scatter_gradients_numpy(dofs, G, W, 97), p2g.scatter_gradients_numba(dofs, G, W, 97))]:
        assert ref.shape == got.shape and np.abs(ref - got).max() < 1e-13 * np.abs(ref).max()


def test_nodal_force_kernel_equals_reference(data):
    from fempm.kernels import p2g

    dofs, S, G, _, _, _ = data
    rng = np.random.default_rng(5)
    n, d = G.shape[0], G.shape[2]
    volume, sigma, fext = rng.random(n), rng.standard_normal((n, d, d)), rng.standard_normal((n, d))
    ref = p2g.nodal_forces_numpy(dofs, S, G, volume, sigma, fext, 97)
    got = p2g.nodal_forces_numba(dofs, S, G, volume, sigma, fext, 97)
    assert np.abs(ref - got).max() < 1e-13 * np.abs(ref).max()


@pytest.mark.parametrize("cell", ["interval", "triangle", "quadrilateral", "tetrahedron", "hexahedron",
                                  "distorted quadrilateral", "distorted hexahedron"])
def test_closed_form_basis_and_pull_back_equal_basix(cell):
    """fempm.kernels.shape: degree-1 values and gradients against basix's tabulation with the
    geometry's inverse Jacobians, and the pull-back (closed form on affine cells, Newton's
    method on multilinear ones) against the geometry's numpy pull-back."""
    import dolfinx.fem
    import dolfinx.mesh as dm
    import fempm
    from mpi4py import MPI

    from fempm.kernels import shape

    comm = MPI.COMM_SELF
    name = cell.split()[-1]
    mesh = {"interval": lambda: dm.create_unit_interval(comm, 7),
            "triangle": lambda: dm.create_unit_square(comm, 5, 4),
            "quadrilateral": lambda: dm.create_unit_square(comm, 5, 4, dm.CellType.quadrilateral),
            "tetrahedron": lambda: dm.create_unit_cube(comm, 3, 3, 2),
            "hexahedron": lambda: dm.create_unit_cube(comm, 3, 2, 2, dm.CellType.hexahedron)}[name]()
    d = mesh.geometry.dim
    if cell.startswith("distorted"):  # every node moved: no cell is a parallelogram (parallelepiped)
        x = mesh.geometry.x
        x[:, :d] += 0.04 * np.sin(7.0 * x[:, :d] + 3.0 * x[:, [1, 0, 0][:d]] + 1.0)
    p = fempm.Particles(mesh, np.random.default_rng(0).random((300, d)) * 0.9 + 0.05, 1.0, 1.0)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (d,)))
    geo = p.locator.geometry
    kind = geo.kernel_cell
    assert geo.affine == (kind == name) and kind == name + ("" if geo.affine else shape.MULTILINEAR)
    assert geo.affine != cell.startswith("distorted")
    x0, K = geo.kernel_geometry
    X = geo.pull_back(p.cells, p.x)  # numpy: affine, or Newton from the cell's centre
    got, inside = shape.cell_pull_back(p.cells, p.x, x0, K, kind, 1e-10)
    assert inside.all() and np.abs(got - X).max() < 1e-14
    S, G, dofs = shape.cell_basis(p.cells, X, K, np.asarray(V.dofmap.list), kind)
    tab = V.element.basix_element.tabulate(1, X)[..., 0]
    assert np.abs(S - tab[0]).max() < 1e-14
    assert np.abs(G - np.transpose(tab[1:], (1, 2, 0)) @ geo.inverse_jacobian(p.cells, X)).max() < 1e-11
    assert np.array_equal(dofs, np.asarray(V.dofmap.list)[p.cells])
    _, inside = shape.cell_pull_back(p.cells, p.x + 2.0, x0, K, kind, 1e-10)
    assert not inside.any()
    c2v, v_offsets, v_cells, owned = p.locator.vertex_star()
    cells, Xn = shape.near_pull_back(np.roll(p.cells, 1), p.x, x0, K, c2v, v_offsets, v_cells, owned, kind, 1e-10)
    found = cells >= 0  # the particles whose cell shares a vertex with the one searched from
    assert found.sum() > 10 and geo.contains(geo.pull_back(cells[found], p.x[found]), 1e-10).all()
    assert np.abs(Xn[found] - geo.pull_back(cells[found], p.x[found])).max() < 1e-14


def _pass_state(simplex: bool, seed: int, multilinear: bool = False, d: int = 2):
    """Random particles in random affine cells of dimension ``d`` (``multilinear``:
    quadrilaterals that are not parallelograms, their vertices in the place of K and x0), a
    random grid, two bodies (neo-Hookean and linear elastic), for the particle passes of
    fempm.kernels.lumped."""
    rng = np.random.default_rng(seed)
    n, ncell, nd, k = 400, 60, 90, d + 1 if simplex else 2 ** d
    cells = rng.integers(0, ncell, n).astype(np.int32)
    X = rng.random((n, d)) * (1.0 / d if simplex else 1.0)
    K = rng.standard_normal((ncell, d, d)) * 3.0
    x0 = corner = rng.random((ncell, d))
    if multilinear:
        J = 0.3 * (np.eye(2) + 0.2 * rng.standard_normal((ncell, 2, 2)))
        K = x0[:, None, :] + np.einsum("cgt,at->cag", J, [[0, 0], [1, 0], [0, 1], [1, 1]])
        K[:, 3] += 0.04 * rng.standard_normal((ncell, 2))
        x0 = K
    cell_dofs = rng.integers(0, nd, (ncell, k)).astype(np.int32)
    F = np.eye(d) + 0.05 * rng.standard_normal((n, d, d))
    c2v = rng.integers(0, 40, (ncell, k)).astype(np.int32)  # a random vertex star
    order = np.argsort(c2v.ravel(), kind="stable")
    v_offsets = np.searchsorted(c2v.ravel()[order], np.arange(41)).astype(np.int32)
    star = Star(c2v, v_offsets, (order // k).astype(np.int32), ncell - 5)
    return dict(star=star, cells=cells, X=X, K=K, x0=x0, cell_dofs=cell_dofs, F=F, v=rng.standard_normal((n, d)),
                x=corner[cells] + rng.random((n, d)) * 0.1, v_new=rng.standard_normal((nd, d)),
                v_old=rng.standard_normal((nd, d)), mass=rng.random(n) + 0.5, volume=rng.random(n) + 0.5,
                volume0=rng.random(n) + 0.5, sigma=rng.standard_normal((n, d, d)),
                body=rng.integers(0, 3, n).astype(np.int32), law=np.array([1, 2, 0]), lam=np.array([3.0, 2.0, 0.0]),
                mu=np.array([1.0, 1.5, 0.0]), modulus=np.array([5.0, 0.0, 6.0]), c=rng.random(n),
                h=rng.random(ncell) + 0.1, g=np.array([0.3, -9.8, 0.2][:d]), fext=rng.standard_normal((n, d)))


def call_p2g(kernel, cells, X, K, cell_dofs, mass, v, volume, sigma, g, fext, out, h, body, modulus, c, group, stride):
    """A P2G kernel called with the arrays of a flat argument list, in the bundles it takes
    (fempm.kernels.bundles; the arrays the pass does not read empty)."""
    d = X.shape[1]
    state = State(np.zeros((0, d)), v, np.zeros((0, d, d)), np.zeros(0), volume, sigma, body, mass)
    laws = Laws(np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0), modulus)
    return kernel(Basis(cells, X, K, cell_dofs), state, laws, Forces(g, fext), out, Stable(h, c),
                  Groups(group, stride, np.zeros(1, dtype=np.bool_)))


def call_g2p(kernel, cells, X, K, cell_dofs, v_new, v_old, flip, dt, by_particle, x, v, F, volume0, volume, sigma, body,
        law, lam, mu, L, x0, tol, left, c2v, v_offsets, v_cells, num_cells, mass, mom, sums, group, rigid):
    """A G2P kernel called with the arrays of a flat argument list, in the bundles it takes."""
    return kernel(Basis(cells, X, K, cell_dofs), GridStep(v_new, v_old, flip, dt, by_particle),
                  State(x, v, F, volume0, volume, sigma, body, mass), Laws(law, lam, mu, np.zeros(len(law))),
                  Moves(x0, tol, left, Star(c2v, v_offsets, v_cells, num_cells)), Outputs(L, mom, sums),
                  Groups(group, 0, rigid))


# affine quads: the Q1 basis of the one, the pull-back of the other; make test-all (27 s cold, 14
# kernel variants: the default run checks the compiled step of every cell against the numpy
# step, tests/stepping/test_compiled_step.py)
@pytest.mark.slow
@pytest.mark.parametrize("cell", ["triangle", "quadrilateral", "quadrilateral-multilinear"])
def test_planar_kernels_equal_the_generic_ones_bit_for_bit(cell):
    """fempm.kernels.planar (scalar 2D) against the dimension-generic passes of
    fempm.kernels.lumped: identical results, not only to round-off, in variants that together
    run every part (those of USL with its bound of the stable time, USF's two and MUSL's two).
    On multilinear quadrilaterals the two compute J(X) in another order: equal to round-off."""
    import itertools

    from fempm.kernels import lumped, planar

    simplex, affine = cell == "triangle", not cell.endswith("multilinear")

    def same(a, b):
        if affine:
            return np.array_equal(a, b)
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        return np.allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(a[np.isfinite(a)]).max(initial=1.0),
                           equal_nan=True)

    def _pass_state_(simplex, seed):
        return _pass_state(simplex, seed, not affine)

    for flags in [(True, True, True, True, True, True), (True, True, False, True, False, False),
                  (False, False, True, False, True, False)]:
        with_dt, has_fext = flags[3], flags[4]
        results = []
        for kernel in (lumped._scatter_kernel(cell, *flags), planar.scatter_kernel(simplex, affine, *flags)):
            s = _pass_state_(simplex, 1)
            out = np.zeros((90, 5))
            t = call_p2g(kernel, s["cells"], s["X"], s["K"], s["cell_dofs"], s["mass"], s["v"], s["volume"], s["sigma"], s["g"],
                       s["fext"] if has_fext else np.zeros((0, 2)), out, s["h"] if with_dt else np.zeros(0),
                       s["body"], s["modulus"], s["c"], np.zeros(0, dtype=np.int64), 0)
            results.append((out, t))
        assert same(results[0][0], results[1][0]) and same(results[0][1], results[1][1]), flags
        if with_dt:
            assert np.isfinite(results[0][1]) and results[0][1] > 0
    for (blend, kinematics, move, remap, totals), by_particle, keep_L in itertools.product(
            [(True, True, True, False, True), (True, False, False, True, False), (False, True, True, False, False),
             (False, False, True, False, True)], [False, True], [False, True]):
        results = []
        for kernel in (lumped._g2p_kernel(cell, blend, kinematics, move, remap, totals),
                       planar.g2p_kernel(simplex, affine, blend, kinematics, move, remap, totals)):
            s = _pass_state_(simplex, 2)
            n = len(s["cells"])
            L = np.zeros((n if keep_L else 0, 2, 2))
            left, mom = np.zeros(n, dtype=np.bool_), np.zeros((90 if remap else 0, 2))
            sums = np.full(5 if totals else 0, np.nan)
            counts = call_g2p(kernel, s["cells"], s["X"], s["K"], s["cell_dofs"], s["v_new"], s["v_old"], 0.9, 1e-2,
                            by_particle, s["x"], s["v"], s["F"], s["volume0"], s["volume"], s["sigma"], s["body"],
                            s["law"], s["lam"], s["mu"], L, s["x0"], 1e-10, left, *s["star"], s["mass"], mom, sums,
                            np.zeros(0, dtype=np.int64), np.zeros(1, dtype=np.bool_))
            results.append((counts, [s[k] for k in ("X", "x", "v", "F", "volume", "sigma", "cells")], L, left, mom,
                            sums))
        (c0, a0, L0, l0, m0, s0), (c1, a1, L1, l1, m1, s1) = results
        assert same(c0, c1) and all(same(a, b) for a, b in zip(a0, a1))
        assert same(L0, L1) and np.array_equal(l0, l1) and same(m0, m1)
        assert same(s0, s1) and np.all(np.isfinite(s0))
        if move:  # some particles stay in their cells, some move to a neighbour, some are not found
            moved = np.count_nonzero(a0[-1] != _pass_state_(simplex, 2)["cells"])
            assert 0 < np.count_nonzero(l0) and 0 < moved and np.count_nonzero(l0) + moved < len(l0)


# 30 s of kernels each: make test-all (the compiled 3D step against the numpy step: tests/stepping/test_compiled_step.py)
@pytest.mark.parametrize("cell", [pytest.param("tetrahedron", marks=pytest.mark.slow),
                                  pytest.param("hexahedron", marks=pytest.mark.slow)])
def test_solid_kernels_equal_the_generic_ones(cell):
    """fempm.kernels.solid (scalar 3D, tetrahedra and affine hexahedra) against the
    dimension-generic passes of fempm.kernels.lumped: equal to round-off (the gradients sum
    in another order), in variants that together run every part, grouped and rigid ones too."""
    import itertools

    from fempm.kernels import lumped, solid

    hexa = cell == "hexahedron"
    none, G = np.zeros(0, dtype=np.int64), 2

    def same(a, b):
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        return np.allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(a[np.isfinite(a)]).max(initial=1.0), equal_nan=True)

    group = np.random.default_rng(8).integers(0, G, 400)
    for flags, grouped in [((True, True, True, True, True, True), False), ((True, True, True, True, False, False), True),
                           ((False, False, True, False, True, False), False)]:
        results = []
        for kernel in (lumped._scatter_kernel(cell, *flags, grouped, grouped),
                       solid.scatter_kernel(hexa, *flags, grouped, grouped)):
            s = _pass_state(True, 1, d=3) if not hexa else _pass_state(False, 1, d=3)
            out = np.zeros((90, 20 if grouped else 7))
            t = call_p2g(kernel, s["cells"], s["X"], s["K"], s["cell_dofs"], s["mass"], s["v"], s["volume"], s["sigma"], s["g"],
                       s["fext"] if flags[4] else np.zeros((0, 3)), out, s["h"] if flags[3] else np.zeros(0),
                       s["body"], s["modulus"], s["c"], group if grouped else none, 10)
            results.append((out, t))
        assert np.abs(results[0][0]).max() > 1.0
        assert same(results[0][0], results[1][0]) and same(results[0][1], results[1][1]), flags
    for (blend, kinematics, move, remap, totals, grouped), by_particle in itertools.product(
            [(True, True, True, False, True, False), (True, False, False, True, False, True),
             (False, True, True, False, False, True), (False, False, True, False, True, False)], [False, True]):
        results = []
        for kernel in (lumped._g2p_kernel(cell, blend, kinematics, move, remap, totals, grouped),
                       solid.g2p_kernel(hexa, blend, kinematics, move, remap, totals, grouped)):
            s = _pass_state(not hexa, 2, d=3)
            n = len(s["cells"])
            L = np.zeros((n, 3, 3))
            left, mom = np.zeros(n, dtype=np.bool_), np.zeros((90 if remap else 0, 3 * G))
            sums = np.full(6 if totals else 0, np.nan)
            vn, vo = (np.hstack([s[k], -s[k]]) if grouped else s[k] for k in ("v_new", "v_old"))
            counts = call_g2p(kernel, s["cells"], s["X"], s["K"], s["cell_dofs"], vn, vo, 0.9, 1e-2, by_particle, s["x"], s["v"],
                            s["F"], s["volume0"], s["volume"], s["sigma"], s["body"], s["law"], s["lam"], s["mu"], L,
                            s["x0"], 1e-10, left, *s["star"], s["mass"], mom, sums, group if grouped else none,
                            np.array([False, True]) if grouped else np.zeros(1, dtype=np.bool_))
            results.append((counts, [s[k] for k in ("X", "x", "v", "F", "volume", "sigma", "cells")], L, left, mom,
                            sums))
        (c0, a0, L0, l0, m0, s0), (c1, a1, L1, l1, m1, s1) = results
        assert same(c0, c1) and all(same(a, b) for a, b in zip(a0, a1))
        assert same(L0, L1) and np.array_equal(l0, l1) and same(m0, m1) and same(s0, s1)
        if kinematics:
            assert np.abs(L0).max() > 1.0


# 20 s of kernels: make test-all (the grouped compiled step against the numpy contact grid:
# tests/stepping/test_contact_compiled.py)
@pytest.mark.slow
@pytest.mark.parametrize("cell", ["triangle", "quadrilateral-multilinear"])
def test_grouped_passes_are_the_one_field_passes_of_each_group(cell):
    """Multi-field contact's passes (a group per particle, fempm.stepping.contact_points): the
    grouped P2G into G = 3 blocks of columns [m | m v | f | grad m] equals the one-field P2G of
    each group's particles into its block, the mass gradients equal a force-only P2G with
    V = M and sigma = -I; the grouped G2P (blend with MUSL's re-map, kinematics, motion) equals
    the one-field G2P of each group's particles from its block, and a rigid group's particles
    keep their velocity and F and move with their velocity. The generic and the planar kernels
    alike."""
    from fempm.kernels import lumped, planar

    simplex, affine = cell == "triangle", not cell.endswith("multilinear")
    s = _pass_state(simplex, 4, not affine)
    n, nd, G, S = len(s["cells"]), 90, 3, 7
    group = np.random.default_rng(5).integers(0, G, n)
    none = np.zeros(0, dtype=np.int64)
    args = ("mass", "v", "volume", "sigma", "g", "fext")
    for grouped, one in ((lumped._scatter_kernel(cell, True, True, True, True, True, False, True, True),
                          lumped._scatter_kernel(cell, True, True, True, True, True, False)),
                         (planar.scatter_kernel(simplex, affine, True, True, True, True, True, False, True, True),
                          planar.scatter_kernel(simplex, affine, True, True, True, True, True, False))):
        out = np.zeros((nd, G * S))
        call_p2g(grouped, s["cells"], s["X"], s["K"], s["cell_dofs"], *[s[k] for k in args], out, s["h"], s["body"],
                s["modulus"], s["c"], group, S)
        for g in range(G):
            k = group == g
            sub = [s[a][k] if a not in ("g",) else s[a] for a in args]
            ref = np.zeros((nd, 5))
            call_p2g(one, s["cells"][k], s["X"][k], s["K"], s["cell_dofs"], *sub, ref, s["h"], s["body"][k], s["modulus"],
                s["c"][k], none, 0)
            assert np.allclose(out[:, g * S:g * S + 5], ref, rtol=0, atol=1e-12 * np.abs(ref).max())
            grad = np.zeros((nd, 5))
            call_p2g(one, s["cells"][k], s["X"][k], s["K"], s["cell_dofs"], s["mass"][k], s["v"][k], s["mass"][k],
                np.broadcast_to(-np.eye(2), (k.sum(), 2, 2)).copy(), 0.0 * s["g"], np.zeros((k.sum(), 2)), grad,
                s["h"], s["body"][k], s["modulus"], s["c"][k], none, 0)
            assert np.abs(out[:, g * S + 5:g * S + 7]).max() > 1.0
            assert np.allclose(out[:, g * S + 5:g * S + 7], grad[:, 3:5], rtol=0, atol=1e-12 * np.abs(grad).max())
    rng = np.random.default_rng(6)
    v_new, v_old = rng.standard_normal((nd, 2 * G)), rng.standard_normal((nd, 2 * G))
    per_particle = ("cells", "X", "x", "v", "F", "volume0", "volume", "sigma", "body", "mass")
    for grouped, one in ((lumped._g2p_kernel(cell, True, True, True, True, False, True),
                          lumped._g2p_kernel(cell, True, True, True, True, False)),
                         (planar.g2p_kernel(simplex, affine, True, True, True, True, False, True),
                          planar.g2p_kernel(simplex, affine, True, True, True, True, False))):
        results = []
        rigid = np.array([False, False, True])  # group 2: a rigid body's particles
        for g in [None, *range(G)]:
            t = _pass_state(simplex, 4, not affine)
            k = np.ones(n, dtype=bool) if g is None else group == g
            t.update({a: np.ascontiguousarray(t[a][k]) for a in per_particle})
            m = k.sum()
            mom, left = np.zeros((nd, 2 * G if g is None else 2)), np.zeros(m, dtype=np.bool_)
            cols = slice(None) if g is None else slice(2 * g, 2 * g + 2)
            vn, vo = np.ascontiguousarray(v_new[:, cols]), np.ascontiguousarray(v_old[:, cols])
            flip, by_particle = 0.9, False
            if g is not None and rigid[g]:  # the reference: no grid increment, L = 0, moved by its own velocity
                vn, vo, flip, by_particle = 0.0 * vn, 0.0 * vo, 1.0, True
            kernel, last = (grouped, (group, rigid)) if g is None else (one, (none, np.zeros(1, dtype=np.bool_)))
            call_g2p(kernel, t["cells"], t["X"], t["K"], t["cell_dofs"], vn, vo, flip, 1e-2, by_particle, t["x"], t["v"], t["F"],
                   t["volume0"], t["volume"], t["sigma"], t["body"], t["law"], t["lam"], t["mu"], np.zeros((0, 2, 2)),
                   t["x0"], 1e-10, left, *t["star"], t["mass"], mom, np.zeros(0), *last)
            results.append((k, [t[a] for a in ("X", "x", "v", "F", "volume", "sigma", "cells")], mom, left))
        _, a0, mom0, left0 = results[0]
        for g, (k, a, mom, left) in enumerate(results[1:]):
            assert all(np.allclose(x[k], y, rtol=0, atol=1e-13 * max(1.0, np.nanmax(np.abs(y))), equal_nan=True)
                       for x, y in zip(a0, a))  # NaN: X of a particle whose pull-back failed, in both
            assert np.allclose(mom0[:, 2 * g:2 * g + 2], mom, rtol=0, atol=1e-13 * np.abs(mom).max())
            assert np.array_equal(left0[k], left)


@pytest.mark.parametrize("d", [2, 3])
def test_plasticity_kernels_equal_their_references(d):
    """The Jaumann predictor and the J2 radial return, compiled against numpy, with about half
    the particles yielding."""
    from fempm.kernels import plasticity as k

    rng = np.random.default_rng(10 + d)
    n = 400
    L = rng.standard_normal((n, d, d))
    sigma = rng.standard_normal((n, d, d))
    sigma = sigma + np.swapaxes(sigma, 1, 2)
    zz = rng.standard_normal(n) if d == 2 else None
    ref = k.jaumann_trial_numpy(L, sigma, zz, 0.05, 3.0, 2.0)
    got = k.jaumann_trial_numba(L, sigma, zz, 0.05, 3.0, 2.0)
    assert np.abs(ref - got).max() < 1e-14 * np.abs(ref).max()
    eps = rng.random(n)
    dev = ref - np.trace(ref, axis1=1, axis2=2)[:, None, None] / 3 * np.eye(3)
    q = np.sqrt(1.5 * np.einsum("nij,nij->n", dev, dev))
    sy = float(np.median(q)) - 0.5 * float(np.median(eps))  # yield stress + H eps_p near the median q
    (S_ref, e_ref), (S_got, e_got) = (f(ref, eps, sy, 0.5, 2.0) for f in (k.von_mises_return_numpy,
                                                                          k.von_mises_return_numba))
    yielded = e_ref > eps
    assert 0.3 < yielded.mean() < 0.7
    assert np.abs(S_ref - S_got).max() < 1e-14 * np.abs(S_ref).max() and np.abs(e_ref - e_got).max() < 1e-15


def test_drucker_prager_kernel_equals_its_reference():
    """Trial stresses that stay elastic, return to the cone, pass the apex or the tension
    cut-off: the compiled return equals numpy's."""
    from fempm.kernels import plasticity as k
    from fempm.materials import DruckerPrager

    rng = np.random.default_rng(5)
    n = 800
    A = rng.standard_normal((n, 3, 3))
    S = (A + np.swapaxes(A, 1, 2)) + rng.uniform(-4.0, 3.0, n)[:, None, None] * np.eye(3)
    eps = rng.random(n)
    law = DruckerPrager(10.0, 0.3, friction_angle=30.0, dilation_angle=10.0, cohesion=1.0, tension=0.5)
    lam, G = law.lame
    args = (*law.parameters(3), G, lam + 2 * G / 3)
    (S_ref, e_ref), (S_got, e_got) = (f(S, eps, *args) for f in (k.drucker_prager_return_numpy,
                                                                  k.drucker_prager_return_numba))
    assert np.abs(S_ref - S_got).max() < 1e-14 * np.abs(S_ref).max() and np.abs(e_ref - e_got).max() < 1e-15
    p_ref = np.trace(S_ref, axis1=1, axis2=2) / 3
    no_deviator = np.abs(S_ref - p_ref[:, None, None] * np.eye(3)).max(axis=(1, 2)) < 1e-12
    plastic = e_ref > eps
    assert 0.1 < plastic.mean() < 0.9
    assert (plastic & no_deviator).any() and (plastic & ~no_deviator).any()  # the apex and the cone
    assert np.isclose(p_ref, 0.5).any()  # the tension cut-off


@pytest.mark.parametrize("cell", ["triangle", "quadrilateral", "quadrilateral-multilinear"])
@pytest.mark.parametrize(("columns", "lumping"), [(2, False), (4, True)])
def test_planar_mass_apply_equals_the_generic_one(cell, columns, lumping):
    """FMPM's M_C y in scalar code (fempm.kernels.fmpm.planar_mass_apply) against the kernel of
    any cell type, with lumped dofs left out of y and M_C 1_l in the last column."""
    from fempm.kernels import fmpm as kf

    rng = np.random.default_rng(columns)
    n, nd, nk = 400, 60, 3 if cell == "triangle" else 4
    cells = rng.integers(0, 30, size=n).astype(np.int32)
    cell_dofs = rng.integers(0, nd, size=(30, nk)).astype(np.int32)
    X = rng.random((n, 2))
    if cell == "triangle":
        X *= 0.5  # inside the reference triangle
    K = rng.random((30, nk, 2))  # the vertices of multilinear cells, read only for gradients
    mass, y = rng.random(n), rng.standard_normal((nd, columns))
    lump = rng.random(nd) < 0.3 if lumping else np.zeros(0, dtype=np.bool_)
    out = [np.zeros((nd, columns + lumping)) for _ in range(2)]
    kf.planar_mass_apply(cell == "triangle")(cells, X, K, cell_dofs, mass, y, lump, out[0])
    kf.generic_mass_apply(cell)(cells, X, K, cell_dofs, mass, y, lump, out[1])
    assert np.abs(out[0]).max() > 1.0
    assert np.allclose(out[0], out[1], rtol=1e-13, atol=1e-13 * np.abs(out[1]).max())


def test_quadrilateral_pull_back_of_a_moved_particle_equals_newtons():
    """fempm.kernels.multilinear.quad_pull_back (closed form, stopping once the next step is
    estimated below the tolerance) against multilinear_pull_back on distorted quadrilaterals:
    points moved from converged reference points, seeded by the first Newton step as the G2P
    pass seeds them, and unseeded points, inside and outside the cells."""
    numba = pytest.importorskip("numba")
    from fempm.kernels.multilinear import multilinear_pull_back, quad_pull_back

    rng = np.random.default_rng(5)
    n = 2000
    square = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])  # basix order
    xc = (square[None] + 0.2 * rng.standard_normal((n, 4, 2))) * rng.uniform(0.01, 10.0, (n, 1, 1))
    xc += rng.uniform(-50.0, 50.0, (n, 1, 2))  # cells far from the origin too
    cells = np.arange(n)

    @numba.njit
    def both(x, seed_X, seeds, X_new, X_ref, inside):
        for p in range(len(x)):
            X_new[p] = seed_X[p]
            X_ref[p] = seed_X[p]
            inside[p, 0] = quad_pull_back(x, p, xc, cells[p], 1e-10, X_new, seeds[p])
            inside[p, 1] = multilinear_pull_back(x, p, xc, cells[p], 2, 1e-10, X_ref)

    X = rng.uniform(-0.2, 1.2, (n, 2))  # half of them outside
    N = np.stack([(1 - X[:, 0]) * (1 - X[:, 1]), X[:, 0] * (1 - X[:, 1]), (1 - X[:, 0]) * X[:, 1], X[:, 0] * X[:, 1]], 1)
    x_old = np.einsum("na,nai->ni", N, xc)
    u = 1e-3 * rng.standard_normal((n, 2)) * np.abs(xc[:, 1] - xc[:, 0]).max(axis=1)[:, None]
    J = np.stack([np.einsum("na,nai->ni", np.stack([-(1 - X[:, 1]), 1 - X[:, 1], -X[:, 1], X[:, 1]], 1), xc),
                  np.einsum("na,nai->ni", np.stack([-(1 - X[:, 0]), -X[:, 0], 1 - X[:, 0], X[:, 0]], 1), xc)], axis=2)
    step = np.linalg.solve(J, u[:, :, None])[:, :, 0]  # the first Newton step from X
    X_new, X_ref, inside = np.empty((n, 2)), np.empty((n, 2)), np.zeros((n, 2), dtype=np.bool_)
    for seed_X, seeds in ((X + step, np.abs(step).max(axis=1)), (np.full((n, 2), 0.5), np.full(n, np.inf))):
        both(x_old + u, seed_X, seeds, X_new, X_ref, inside)
        assert np.array_equal(inside[:, 0], inside[:, 1]) and 0.4 < inside[:, 0].mean() < 0.65
        ok = np.isfinite(X_ref).all(axis=1)
        assert ok.mean() > 0.95 and np.array_equal(ok, np.isfinite(X_new).all(axis=1))
        assert np.abs(X_new[ok] - X_ref[ok]).max() < 1e-12


@pytest.mark.parametrize("cell", ["triangle", "quadrilateral"])
def test_planar_corner_location_equals_the_generic_one_bit_for_bit(cell):
    """CPDI1's corners made and located in scalar code (fempm.kernels.cpdi1, affine triangles
    and quadrilaterals) against the dimension-generic kernel: the same cells and reference
    coordinates, with and without the last step's cells as guesses, found in the guess, the
    particle's cell, its vertex star or nowhere."""
    from fempm.kernels import cpdi1
    from fempm.particles.corners import corner_signs

    s = _pass_state(cell == "triangle", 4)
    n, signs = len(s["cells"]), corner_signs(2)
    lp = np.full((n, 2), 0.05) * (1.0 + np.random.default_rng(2).random((n, 1)))
    guesses = [np.zeros((0, 4), dtype=np.int32), np.random.default_rng(3).integers(-1, 60, (n, 4)).astype(np.int32)]
    for guess in guesses:
        got = []
        for kernel in (cpdi1._planar_locate_kernel(cell == "triangle"), cpdi1._locate_kernel(cell)):
            sc, Y = np.full((n, 4), -7, dtype=np.int32), np.zeros((4 * n, 2))
            missing = kernel(s["x"], s["F"], lp, signs, s["cells"], s["x0"], s["K"], s["star"], 1e-10, guess, sc, Y)
            got.append((missing, sc, Y))
        (m0, sc0, Y0), (m1, sc1, Y1) = got
        found = sc0 >= 0
        assert m0 == m1 and np.array_equal(sc0, sc1) and m0 > 0 and found.sum() > n
        assert np.array_equal(Y0[found.ravel()], Y1[found.ravel()])
