r"""Exact integrals of a DOLFINx basis over axis-aligned boxes cut by the mesh cells (GIMP).

For a particle box :math:`\Omega_p` (centre :math:`x_p`, half-widths :math:`\ell_p`) and a
cell :math:`c`, the piece :math:`\Omega_p \cap c` is integrated with a rule exact for the
basis on that piece:

* intervals, and quadrilaterals / hexahedra that are axis-aligned boxes (affine with a
  diagonal Jacobian): the piece is a box; a tensor Gauss-Legendre rule of :math:`k + 1`
  points per axis integrates :math:`Q_k` exactly;
* triangles and tetrahedra, and other quadrilaterals / hexahedra split into triangles /
  tetrahedra (2 and 6 per cell): every simplex is clipped by the box's :math:`2d` half-spaces
  (a simplex cut by a plane keeps a simplex or a prism, split again into simplices), and each
  simplex of the piece gets a Gauss rule of degree :math:`k` (affine simplices: exact for
  :math:`P_k`), :math:`dk` (parallelogram / parallelepiped cells: exact for :math:`Q_k`) or
  :math:`dk + 2` (non-affine cells, whose basis is not a polynomial in :math:`x`: accurate to
  that rule, and hexahedra with non-planar faces are split along their diagonals).

:meth:`BoxIntegrator.integrals` returns, per (particle, dof), :math:`\int_{\Omega_p \cap \Omega_h} N_i`,
:math:`\int_{\Omega_p \cap \Omega_h} \nabla N_i` and the covered volume
:math:`|\Omega_p \cap \Omega_h|` over the cells it is given (a rank's owned cells). The part of
a box outside the mesh is cut off: :class:`fempm.transfer.domains.GIMP` divides by the covered volume,
which keeps the partition of unity (see there).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import basix
import numpy as np
import numpy.typing as npt

from fempm.meshes.geometry import CellGeometry
from fempm.particles.cell_bins import CellBins

__all__ = ["BoxIntegrals", "BoxIntegrator", "clip_simplices"]

#: the simplices of one reference cell, as indices into its geometry nodes (DOLFINx order)
_SPLIT = {
    "interval": [[0, 1]],
    "triangle": [[0, 1, 2]],
    "tetrahedron": [[0, 1, 2, 3]],
    "quadrilateral": [[0, 1, 3], [0, 3, 2]],
    # Kuhn split of the cube along the diagonal 0-7 (vertex v = 4 z + 2 y + x)
    "hexahedron": [[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]],
}
_SIMPLEX = {1: basix.CellType.interval, 2: basix.CellType.triangle, 3: basix.CellType.tetrahedron}


@dataclass
class BoxIntegrals:
    """Integrals over the boxes' parts in the given cells, one row per (box, cell dof):
    ``box`` (r,), local ``dofs`` (r,), ``N`` (r,) and ``dN`` (r, d) (or None); and the covered
    volume of each box, ``volume`` (m,)."""

    box: npt.NDArray[np.int64]
    dofs: npt.NDArray[np.int32]
    N: npt.NDArray
    dN: npt.NDArray | None
    volume: npt.NDArray


def clip_simplices(P: npt.NDArray, lo: npt.NDArray, hi: npt.NDArray) -> tuple[npt.NDArray, npt.NDArray]:
    r"""The parts of simplices ``P`` (m, d + 1, d) inside the boxes ``[lo, hi]`` (m, d) as
    simplices (k, d + 1, d) with the index of the simplex each came from (k,).

    The box's half-spaces cut one after the other: a simplex with ``j`` of its ``d + 1``
    vertices inside a plane keeps a simplex (``j = 1``), a quadrilateral (2D, ``j = 2``: two
    triangles) or a prism (3D, ``j = 2, 3``: three tetrahedra
    :math:`(a_0 a_1 a_2 b_0), (a_1 a_2 b_0 b_1), (a_2 b_0 b_1 b_2)`)."""
    m, k, d = P.shape
    inside_box = (P >= lo[:, None, :]) & (P <= hi[:, None, :])  # (m, k, d)
    whole = inside_box.all(axis=(1, 2))
    apart = ((P < lo[:, None, :]).all(axis=1) | (P > hi[:, None, :]).all(axis=1)).any(axis=1)
    cut_by = np.flatnonzero(~whole & ~apart)  # only these meet a plane of their box
    kept, kept_parent = [P[whole]], [np.flatnonzero(whole)]
    P, parent = P[cut_by], cut_by
    # vertex orders with the inside vertices first, by the bit mask of inside vertices
    masks = np.arange(2**k)
    table = np.array([np.argsort([-((mk >> v) & 1) for v in range(k)], kind="stable") for mk in masks])
    for a, side in itertools.product(range(d), (-1.0, 1.0)):
        bound = (lo if side < 0 else hi)[parent, a]
        s = side * (P[:, :, a] - bound[:, None])  # <= 0 inside
        inside = s <= 0.0
        nin = inside.sum(axis=1)
        keep = nin == k
        pieces, parents = [P[keep]], [parent[keep]]
        order_all = table[inside.astype(np.int64) @ (1 << np.arange(k))]
        for j in range(1, k):
            sel = np.flatnonzero(nin == j)
            if sel.size == 0:
                continue
            order = order_all[sel]
            V = np.take_along_axis(P[sel], order[:, :, None], axis=1)
            S = np.take_along_axis(s[sel], order, axis=1)

            def cut(i, o, V=V, S=S):  # the point where edge (i, o) crosses the plane
                t = S[:, i] / (S[:, i] - S[:, o])
                return V[:, i] + t[:, None] * (V[:, o] - V[:, i])

            for simplex in _pieces(d, j, V, cut):
                pieces.append(simplex)
                parents.append(parent[sel])
        P, parent = np.concatenate(pieces), np.concatenate(parents)
    return np.concatenate(kept + [P]), np.concatenate(kept_parent + [parent])


def _pieces(d: int, j: int, V: npt.NDArray, cut) -> list[npt.NDArray]:
    """The simplices of a simplex with its first ``j`` vertices inside a half-space."""
    st = lambda *pts: np.stack(pts, axis=1)  # noqa: E731
    if j == 1:
        return [st(V[:, 0], *(cut(0, o) for o in range(1, d + 1)))]
    if d == 2:  # j = 2: the quadrilateral v0 v1 p12 p02
        p12, p02 = cut(1, 2), cut(0, 2)
        return [st(V[:, 0], V[:, 1], p12), st(V[:, 0], p12, p02)]
    if j == 2:  # d = 3: prism (v0, p02, p03) - (v1, p12, p13)
        a, b = (V[:, 0], cut(0, 2), cut(0, 3)), (V[:, 1], cut(1, 2), cut(1, 3))
    else:  # d = 3, j = 3: prism (v0, v1, v2) - (p03, p13, p23)
        a, b = (V[:, 0], V[:, 1], V[:, 2]), (cut(0, 3), cut(1, 3), cut(2, 3))
    return [st(a[0], a[1], a[2], b[0]), st(a[1], a[2], b[0], b[1]), st(a[2], b[0], b[1], b[2])]


def _simplex_rule(P: npt.NDArray, degree: int) -> tuple[npt.NDArray, npt.NDArray]:
    """Physical Gauss points (m, q, d) and weights (m, q) of a degree-``degree`` rule on each
    simplex of ``P`` (m, d + 1, d)."""
    d = P.shape[2]
    Xq, wq = basix.make_quadrature(_SIMPLEX[d], max(degree, 1))
    E = P[:, 1:, :] - P[:, :1, :]  # (m, d, d) rows: edge vectors
    x = P[:, None, 0, :] + np.einsum("qk,mkg->mqg", Xq, E)
    return x, np.abs(np.linalg.det(E))[:, None] * wq[None, :]


class BoxIntegrator:
    """Integrates the basis of a Lagrange space over boxes cut by a set of cells (see the
    module docstring); built once per mesh, space and cell set.

    ``geometry``: the mesh's :class:`CellGeometry`; ``element``: the space's basix element;
    ``space_dofs``: its dofmap (``V.dofmap.list``); ``bins``: the cells to integrate over
    (:class:`CellBins`, e.g. :attr:`fempm.particles.location.CellLocator.cell_bins`, the owned cells)."""

    def __init__(self, geometry: CellGeometry, element: basix.finite_element.FiniteElement,
                 space_dofs: npt.NDArray[np.int32], bins: CellBins):
        self.geometry, self.element, self.space_dofs = geometry, element, np.asarray(space_dofs)
        self.bins = bins
        d, k = geometry.gdim, element.degree
        name = geometry.cell_name
        self.tensor = name == "interval" or (name in ("quadrilateral", "hexahedron") and geometry.axis_aligned)
        if name in ("interval", "triangle", "tetrahedron"):
            self.degree = k
        else:
            self.degree = d * k if geometry.affine else d * k + 2
        xi, wi = np.polynomial.legendre.leggauss(k + 1)
        self._gauss = ((np.array(list(itertools.product(xi, repeat=d))) + 1.0) / 2.0,
                       np.prod(np.array(list(itertools.product(wi, repeat=d))), axis=1) / 2**d)
        self._split = np.array(_SPLIT[name])

    def points(self, lo: npt.NDArray, hi: npt.NDArray):
        """Quadrature points of the boxes' parts in the cells, flat: box index, cell, physical
        point (r, d) and weight (r,)."""
        box, pos = self.bins.candidates(lo, hi)
        cell = self.bins.cells[pos]
        if self.tensor:  # the piece is the box [max(lo), min(hi)]
            a = np.maximum(lo[box], self.bins.lo[pos])
            b = np.minimum(hi[box], self.bins.hi[pos])
            ok = np.all(b > a, axis=1)
            box, cell, a, b = box[ok], cell[ok], a[ok], b[ok]
            ref, w = self._gauss
            x = a[:, None, :] + ref[None, :, :] * (b - a)[:, None, :]
            wts = np.prod(b - a, axis=1)[:, None] * w[None, :]
        else:
            nodes = self.geometry.x[self.geometry.dofmap[cell]]  # the vertices come first
            S = nodes[:, self._split, :].reshape(-1, self._split.shape[1], nodes.shape[2])
            pair = np.repeat(np.arange(len(box)), len(self._split))
            pieces, parent = clip_simplices(S, lo[box[pair]], hi[box[pair]])
            x, wts = _simplex_rule(pieces, self.degree)
            box, cell = box[pair[parent]], cell[pair[parent]]
        q = x.shape[1]
        return np.repeat(box, q), np.repeat(cell, q), x.reshape(-1, x.shape[2]), wts.ravel()

    def integrals(self, lo: npt.NDArray, hi: npt.NDArray, gradients: bool) -> BoxIntegrals:
        """:math:`\\int N_i` and, with ``gradients``, :math:`\\int \\nabla N_i` per (box, local dof),
        and the covered volumes, of the boxes ``[lo, hi]`` (m, d) cut by this integrator's cells."""
        box, cell, x, w = self.points(lo, hi)
        volume = np.bincount(box, weights=w, minlength=len(lo))
        X = self.geometry.pull_back(cell, x)
        tab = self.element.tabulate(1 if gradients else 0, np.ascontiguousarray(X))[..., 0]
        k, d = self.element.dim, x.shape[1]
        dN = None
        if gradients:
            K = self.geometry.inverse_jacobian(cell, X)
            dN = ((np.transpose(tab[1:], (1, 2, 0)) @ K) * w[:, None, None]).reshape(-1, d)
        return BoxIntegrals(np.repeat(box, k), self.space_dofs[cell].ravel(), (tab[0] * w[:, None]).ravel(), dN, volume)
