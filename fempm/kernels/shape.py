r"""Degree-1 Lagrange basis in closed form on affine cells (simplices, parallelograms,
parallelepipeds) and on multilinear cells (any quadrilateral or hexahedron with straight
edges), degree 2 on affine simplices (:mod:`fempm.kernels.degree2`), and the pull-back.

On a cell :math:`c` with :math:`x = x_0 + J X` and :math:`K = J^{-1}`:

.. math::
    X = K (x - x_0), \qquad \nabla N_a(x) = \nabla_X \hat N_a(X)\, K,

with :math:`\hat N_0 = 1 - \sum_t X_t`, :math:`\hat N_{a} = X_{a-1}` on simplices and
:math:`\hat N_a = \prod_t \big(X_t \text{ if bit } t \text{ of } a \text{ else } 1 - X_t\big)`
on the reference square and cube (basix's vertex order: vertex ``a`` has coordinate ``t``
equal to bit ``t`` of ``a``). The pull-back's inside test is :meth:`fempm.meshes.geometry.CellGeometry.contains`.

On a multilinear cell (kernel cell type ``"quadrilateral" + MULTILINEAR``) the map is
:math:`x(X) = \sum_a \hat N_a(X) x_a` over its vertices, :math:`K = J(X)^{-1}` is evaluated at
each point and the pull-back is Newton's method (:mod:`fempm.kernels.multilinear`),
:math:`X \leftarrow X - J(X)^{-1} (x(X) - x)` (the numpy
reference is :meth:`fempm.meshes.geometry.CellGeometry.pull_back`). The kernels receive the
cells' vertices (cells, k, gdim) in the place of ``K`` and ``x0``.

:func:`cell_basis` fills the per-particle arrays of :class:`fempm.transfer.basis.ParticleBasis`
(basix tabulation and the geometry's inverse Jacobians are its reference);
:func:`cell_pull_back` serves :meth:`fempm.particles.location.CellLocator.relocate`. The other kernels
evaluate the basis on the fly with :func:`shape` instead of storing it.
"""

from __future__ import annotations

import functools
from types import SimpleNamespace

import numpy as np
import numpy.typing as npt

from fempm.kernels.choice import COMPILED, INLINE

__all__ = ["AVAILABLE", "BERNSTEIN2", "CELLS", "LAGRANGE2", "MULTILINEAR", "cell_basis", "cell_pull_back", "is_affine",
           "near_pull_back", "space_of", "vertex_star_pull_back"]

try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency
    njit = None

if njit is not None:
    from fempm.kernels.degree2 import degree2
    from fempm.kernels.multilinear import multilinear_pull_back, multilinear_shape

    @njit(inline=INLINE)
    def shape(X, p, K, c, simplex, affine, t, k, N, G, degree=1, bernstein=False):  # pragma: no cover - compiled
        """Values ``N`` (k,) and physical gradients ``G`` (k, t) of particle ``p`` at reference
        point ``X[p]`` in cell ``c`` with inverse Jacobian ``K[c]`` (gdim = tdim = ``t``); on
        multilinear cells (not ``affine``) ``K`` holds the vertices (cells, k, t) and the
        inverse Jacobian is computed at ``X[p]``. ``degree`` 2 (simplices): the Lagrange or
        ``bernstein`` basis of :func:`degree2`. Inlined: where ``simplex``, ``affine``, ``t``,
        ``k``, ``degree`` and ``bernstein`` are compile-time constants (the kernels of
        :func:`fempm.kernels.lumped.kernels_for`) the loops unroll and the branches fold."""
        if not affine:
            multilinear_shape(X, p, K, c, t, k, N, G)
        elif simplex:
            s = 1.0
            for i in range(t):
                s -= X[p, i]
            N[0] = s
            for e in range(t):
                g = 0.0
                for i in range(t):
                    g -= K[c, i, e]
                G[0, e] = g
            for a in range(1, t + 1):
                N[a] = X[p, a - 1]
                for e in range(t):
                    G[a, e] = K[c, a - 1, e]
            if degree == 2:
                degree2(t, k, bernstein, N, G, True)
        else:
            for a in range(k):
                v = 1.0
                for i in range(t):
                    v *= X[p, i] if (a >> i) & 1 else 1.0 - X[p, i]
                N[a] = v
                for e in range(t):
                    G[a, e] = 0.0
                for j in range(t):
                    g = 1.0
                    for i in range(t):
                        if i == j:
                            g *= 1.0 if (a >> i) & 1 else -1.0
                        else:
                            g *= X[p, i] if (a >> i) & 1 else 1.0 - X[p, i]
                    for e in range(t):
                        G[a, e] += g * K[c, j, e]

    @njit(inline=INLINE)
    def shape_values(X, p, simplex, t, k, N):  # pragma: no cover - compiled
        """The values ``N`` (k,) of :func:`shape` alone (no gradients, no Jacobian)."""
        if simplex:
            s = 1.0
            for i in range(t):
                s -= X[p, i]
            N[0] = s
            for a in range(1, k):
                N[a] = X[p, a - 1]
        else:
            for a in range(k):
                v = 1.0
                for i in range(t):
                    v *= X[p, i] if (a >> i) & 1 else 1.0 - X[p, i]
                N[a] = v

    @njit(inline="always")  # (always: the multilinear branch types only where affine is the caller's constant)
    def inside_after_pull_back(x, p, x0, K, c, simplex, t, tol, X, affine=True):  # pragma: no cover - compiled
        """X[p] <- K[c] (x[p] - x0[c]); whether it lies in the reference cell within ``tol``
        (:meth:`fempm.meshes.geometry.CellGeometry.contains`; NaN lies outside). Not
        ``affine``: ``K`` holds the cells' vertices and :func:`multilinear_pull_back` pulls back."""
        if not affine:
            return multilinear_pull_back(x, p, K, c, t, tol, X)
        ok = True
        s = 0.0
        for i in range(t):
            r = 0.0
            for e in range(t):
                r += K[c, i, e] * (x[p, e] - x0[c, e])
            X[p, i] = r
            s += r
            if not (r >= -tol) or (not simplex and not (r <= 1.0 + tol)):
                ok = False
        if simplex and not (s <= 1.0 + tol):
            ok = False
        return ok

    @njit(inline="always")  # (always: the multilinear branch types only where affine is the caller's constant)
    def star_search(x, p, x0, K, c0, star, simplex, t, tol, X, affine=True):  # pragma: no cover - compiled
        """The lowest-numbered cell below ``num_cells`` other than ``c0`` sharing a vertex with
        it (``star`` = (``c2v``, ``v_offsets``, ``v_cells``, ``num_cells``),
        :class:`fempm.kernels.bundles.Star`: cell -> vertices ``c2v``, vertex -> cells
        ``v_offsets``/``v_cells``) that contains point ``x[p]`` within ``tol``, and ``X[p]`` its
        reference coordinates there; -1 (and ``X[p]`` undefined) if none does (``affine``: see
        :func:`inside_after_pull_back`)."""
        c2v, v_offsets, v_cells, num_cells = star
        best = -1
        for a in range(c2v.shape[1]):
            v = c2v[c0, a]
            for q in range(v_offsets[v], v_offsets[v + 1]):
                e = v_cells[q]
                if e >= num_cells or e == c0 or (best >= 0 and e >= best):
                    continue
                if inside_after_pull_back(x, p, x0, K, e, simplex, t, tol, X, affine):
                    best = e
        if best >= 0:
            inside_after_pull_back(x, p, x0, K, best, simplex, t, tol, X, affine)
        return best


#: the name of a kernel's cell type for cells whose map is multilinear, not affine (quadrilaterals
#: that are not parallelograms, hexahedra that are not parallelepipeds): ``"quadrilateral" + MULTILINEAR``
MULTILINEAR = "-multilinear"
#: cell type -> (dimension, vertices, simplex)
CELLS = {"interval": (1, 2, True), "triangle": (2, 3, True), "tetrahedron": (3, 4, True),
         "quadrilateral": (2, 4, False), "hexahedron": (3, 8, False),
         "quadrilateral" + MULTILINEAR: (2, 4, False), "hexahedron" + MULTILINEAR: (3, 8, False)}
#: the suffixes of the kernel cell types of the degree-2 Lagrange and Bernstein spaces on affine
#: simplices: ``"triangle" + LAGRANGE2`` (the other kernel cell types are of degree-1 spaces)
LAGRANGE2, BERNSTEIN2 = "-P2", "-bernstein2"
for _name in ("interval", "triangle", "tetrahedron"):
    _t = CELLS[_name][0]
    CELLS[_name + LAGRANGE2] = CELLS[_name + BERNSTEIN2] = (_t, (_t + 1) * (_t + 2) // 2, True)


def is_affine(cell: str) -> bool:
    """Whether the kernels of ``cell`` (a key of :data:`CELLS`) see affine cells."""
    return not cell.endswith(MULTILINEAR)


def space_of(cell: str) -> tuple[int, bool]:
    """(degree, Bernstein) of the space of the kernel cell type ``cell`` (a key of :data:`CELLS`)."""
    if cell.endswith(LAGRANGE2):
        return 2, False
    return (2, True) if cell.endswith(BERNSTEIN2) else (1, False)


@functools.cache
def _basis_kernel(cell: str):
    """The per-particle basis of one kernel cell type, its sizes compile-time constants."""
    D, NK, SIMPLEX = CELLS[cell]
    AFFINE = is_affine(cell)
    DEGREE, BERNSTEIN = space_of(cell)

    @njit(cache=True, error_model="numpy")
    def cell_basis(cells, X, K, cell_dofs, S, G, dofs):  # pragma: no cover - compiled
        Np = np.empty(NK)
        Gp = np.empty((NK, D))
        for p in range(len(cells)):
            c = cells[p]
            shape(X, p, K, c, SIMPLEX, AFFINE, D, NK, Np, Gp, DEGREE, BERNSTEIN)
            for a in range(NK):
                S[p, a] = Np[a]
                dofs[p, a] = cell_dofs[c, a]
                for e in range(D):
                    G[p, a, e] = Gp[a, e]

    return cell_basis


@functools.cache
def _pull_back_kernels(cell: str) -> SimpleNamespace:
    """The pull-backs of whole arrays of points for one kernel cell type (its dimension, the
    simplex test and the affine or multilinear map compile-time constants): ``cell``,
    ``near`` and ``star`` serve :func:`cell_pull_back`, :func:`near_pull_back` and
    :func:`vertex_star_pull_back`."""
    D, _, SIMPLEX = CELLS[cell]
    AFFINE = is_affine(cell)

    @njit(cache=True)
    def cell_kernel(cells, x, x0, K, tol, X, inside):  # pragma: no cover - compiled
        for p in range(len(cells)):
            if cells[p] < 0:
                X[p, :] = 0.0
                inside[p] = False
            else:
                inside[p] = inside_after_pull_back(x, p, x0, K, cells[p], SIMPLEX, D, tol, X, AFFINE)

    @njit(cache=True)
    def star_kernel(x, verts, x0, K, v_offsets, v_cells, num_cells, tol, cells, X):  # pragma: no cover - compiled
        for p in range(len(x)):
            best = -1
            for a in range(verts.shape[1]):
                v = verts[p, a]
                if v < 0:
                    continue
                for q in range(v_offsets[v], v_offsets[v + 1]):
                    e = v_cells[q]
                    if e >= num_cells or (best >= 0 and e >= best):
                        continue
                    if inside_after_pull_back(x, p, x0, K, e, SIMPLEX, D, tol, X, AFFINE):
                        best = e
            if best >= 0:
                inside_after_pull_back(x, p, x0, K, best, SIMPLEX, D, tol, X, AFFINE)
            cells[p] = best

    @njit(cache=True)
    def near_kernel(previous, x, x0, K, c2v, v_offsets, v_cells, num_cells, tol, cells, X):  # pragma: no cover
        for p in range(len(previous)):
            cells[p] = star_search(x, p, x0, K, previous[p], (c2v, v_offsets, v_cells, num_cells), SIMPLEX, D, tol, X,
                                   AFFINE)

    return SimpleNamespace(cell=cell_kernel, near=near_kernel, star=star_kernel)


def cell_basis(cells: npt.NDArray[np.int32], X: npt.NDArray, K: npt.NDArray, cell_dofs: npt.NDArray[np.int32],
               cell: str) -> tuple[npt.NDArray, npt.NDArray, npt.NDArray[np.int32]]:
    """(S (n, k), G (n, k, gdim), dofs (n, k)) of the degree-1 space with cell dofmap
    ``cell_dofs`` at reference points ``X`` of ``cells`` (kernel cell type ``cell``, ``K`` per
    cell: :attr:`fempm.meshes.geometry.CellGeometry.kernel_geometry`)."""
    n, k, g = len(cells), cell_dofs.shape[1], X.shape[1]
    S, G, dofs = np.empty((n, k)), np.empty((n, k, g)), np.empty((n, k), dtype=np.int32)
    _basis_kernel(cell)(cells, np.ascontiguousarray(X), K, np.ascontiguousarray(cell_dofs), S, G, dofs)
    return S, G, dofs


def cell_pull_back(cells: npt.NDArray[np.int32], x: npt.NDArray, x0: npt.NDArray, K: npt.NDArray, cell: str,
                   tol: float) -> tuple[npt.NDArray, npt.NDArray[np.bool_]]:
    """Reference coordinates (n, tdim) of points ``x`` in ``cells`` (-1: none) and whether each
    lies inside its cell within ``tol`` (kernel cell type ``cell``, geometry ``x0``, ``K``:
    :attr:`fempm.meshes.geometry.CellGeometry.kernel_geometry`)."""
    X, inside = np.full((len(cells), x.shape[1]), np.nan), np.empty(len(cells), dtype=np.bool_)
    _pull_back_kernels(cell).cell(np.asarray(cells, dtype=np.int32), np.ascontiguousarray(x), x0, K, float(tol), X,
                                  inside)
    return X, inside


def near_pull_back(previous: npt.NDArray[np.int32], x: npt.NDArray, x0: npt.NDArray, K: npt.NDArray,
                   c2v: npt.NDArray[np.int32], v_offsets: npt.NDArray[np.int32], v_cells: npt.NDArray[np.int32],
                   num_cells: int, cell: str, tol: float) -> tuple[npt.NDArray[np.int32], npt.NDArray]:
    """For points ``x`` that left their ``previous`` cells: the lowest-numbered cell below
    ``num_cells`` sharing a vertex with the previous one (cell -> vertices ``c2v``, vertex ->
    cells ``v_offsets``/``v_cells``) that contains the point within ``tol`` (-1: none), and the
    reference coordinates there (kernel cell type ``cell``, geometry ``x0``, ``K``)."""
    cells, X = np.empty(len(previous), dtype=np.int32), np.full((len(previous), x.shape[1]), np.nan)
    _pull_back_kernels(cell).near(np.asarray(previous, dtype=np.int32), np.ascontiguousarray(x), x0, K,
                                  np.ascontiguousarray(c2v), v_offsets, v_cells, int(num_cells), float(tol), cells, X)
    return cells, X


#: whether the closed-form kernels of this module are available (numba installed and selected)
AVAILABLE = COMPILED and njit is not None


def vertex_star_pull_back(x: npt.NDArray, verts: npt.NDArray[np.int32], x0: npt.NDArray, K: npt.NDArray,
                          v_offsets: npt.NDArray[np.int32], v_cells: npt.NDArray[np.int32], num_cells: int,
                          cell: str, tol: float) -> tuple[npt.NDArray[np.int32], npt.NDArray]:
    """For points ``x`` and vertices ``verts`` (n, k; -1: none): the lowest-numbered cell below
    ``num_cells`` holding one of the point's vertices (vertex -> cells ``v_offsets``/``v_cells``)
    that contains the point within ``tol`` (-1: none), and the reference coordinates there
    (kernel cell type ``cell``, geometry ``x0``, ``K``)."""
    cells, X = np.empty(len(x), dtype=np.int32), np.full((len(x), x.shape[1]), np.nan)
    _pull_back_kernels(cell).star(np.ascontiguousarray(x), np.ascontiguousarray(verts, dtype=np.int32), x0, K,
                                  v_offsets, v_cells, int(num_cells), float(tol), cells, X)
    return cells, X
