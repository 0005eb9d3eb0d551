r"""Reference-to-physical maps of the mesh cells, vectorized over points.

For a cell with geometry nodes :math:`x_k` and coordinate basis :math:`\phi_k`,

.. math::
    x(X) = \sum_k \phi_k(X)\, x_k, \qquad J(X) = \sum_k x_k \otimes \nabla_X \phi_k(X),
    \qquad K = J^{-1}.

Affine simplices store :math:`x_0` and :math:`K` per cell, so the pull-back is closed form,
:math:`X = K (x - x_0)`. Other cells (quadrilaterals, hexahedra, curved cells) are pulled back
by a Newton iteration vectorized over all points at once.
"""

from __future__ import annotations

import basix
import dolfinx
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.kernels.shape import MULTILINEAR

__all__ = ["CHUNK", "SIMPLICES", "CellGeometry", "coordinate_map"]

SIMPLICES = {"interval", "triangle", "tetrahedron"}
#: cells per chunk of the whole-mesh set-up (bounds its temporaries)
CHUNK = 65536


def coordinate_map(mesh: dolfinx.mesh.Mesh):
    """The mesh's coordinate element and geometry dofmap (DOLFINx 0.10 and 0.11)."""
    geom = mesh.geometry
    cmap = geom.cmaps[0] if hasattr(geom, "cmaps") else geom.cmap
    dofmap = geom.dofmaps[0] if hasattr(geom, "dofmaps") else geom.dofmap
    return cmap, dofmap


class CellGeometry:
    """Vectorized geometry of the cells of a DOLFINx mesh (push-forward, Jacobian, pull-back).

    Only manifolds with ``gdim == tdim`` are supported (a point must have a unique reference
    coordinate in a cell).
    """

    def __init__(self, mesh: dolfinx.mesh.Mesh):
        self.mesh = mesh
        self.tdim = mesh.topology.dim
        self.gdim = mesh.geometry.dim
        if self.gdim != self.tdim:
            raise NotImplementedError(
                f"fempm needs gdim == tdim (got gdim={self.gdim}, tdim={self.tdim}); create the "
                "mesh with the geometric dimension of its cells (e.g. gdim=2 for triangles)"
            )
        self.cell_name = mesh.topology.cell_type.name
        cmap, dofmap = coordinate_map(mesh)
        self.basix_cell = getattr(basix.CellType, self.cell_name)
        self.element = basix.create_element(
            basix.ElementFamily.P, self.basix_cell, cmap.degree, basix.LagrangeVariant(cmap.variant)
        )
        self.dofmap = np.asarray(dofmap)
        self.x = mesh.geometry.x[:, : self.gdim]
        self.num_owned = mesh.topology.index_map(self.tdim).size_local
        self.degree = cmap.degree
        self.affine = False
        self._vertices: npt.NDArray | None = None
        #: affine cells: the first vertex x0 (cells, gdim) and the inverse Jacobian K (cells, tdim, gdim)
        #: of each cell's map x = x0 + J X (None for other cells)
        self.x0: npt.NDArray | None = None
        self.K: npt.NDArray | None = None
        if cmap.degree == 1:
            # the map is affine when every geometry node is x0 + J X_node with J from the nodes at
            # the reference unit points (simplices always; parallelogram quads, parallelepiped
            # hexes); checked in chunks of cells, keeping x0 and K = J^-1 per cell (J and det J
            # are recomputed from the nodes when asked, by the same arithmetic)
            ref = basix.geometry(self.basix_cell)
            self._unit = [int(np.flatnonzero(np.all(np.isclose(ref, e), axis=1))[0]) for e in np.eye(self.tdim)]
            n = len(self.dofmap)
            x0 = np.empty((n, self.gdim))
            K = np.empty((n, self.tdim, self.gdim))
            scale = np.abs(self.x).max(initial=1.0)
            worst = 0.0
            for start in range(0, n, CHUNK):
                cells = np.arange(start, min(start + CHUNK, n))
                nodes = self.x[self.dofmap[cells]]  # (chunk, nnodes, gdim)
                J = self._nodal_jacobian(nodes)
                pred = nodes[:, :1, :] + np.einsum("cgt,kt->ckg", J, ref)
                worst = max(worst, float(np.abs(pred - nodes).max(initial=0.0)))
                x0[cells] = nodes[:, 0, :]
                if worst <= 1e-13 * scale:
                    K[cells] = np.linalg.inv(J)
            self.affine = bool(mesh.comm.allreduce(worst <= 1e-13 * scale, op=MPI.LAND))
            if self.affine:
                self.x0, self.K = x0, K

    @property
    def kernel_cell(self) -> str | None:
        """The cell type of the compiled kernels (a key of :data:`fempm.kernels.shape.CELLS`):
        the cell's name on affine cells, with :data:`~fempm.kernels.shape.MULTILINEAR` on
        quadrilaterals and hexahedra with straight edges that are not affine; None for curved
        cells (a coordinate map of degree 2 or more)."""
        if self.affine:
            return self.cell_name
        if self.degree == 1 and self.cell_name in ("quadrilateral", "hexahedron"):
            return self.cell_name + MULTILINEAR
        return None

    @property
    def kernel_geometry(self) -> tuple[npt.NDArray, npt.NDArray]:
        """The cell geometry the compiled kernels take as ``(x0, K)``: on affine cells the first
        vertex and the inverse Jacobian of each cell, on multilinear cells its vertices
        (cells, vertices, gdim; made on first use) in both places."""
        if self.affine:
            return self.x0, self.K
        if self._vertices is None:
            self._vertices = np.ascontiguousarray(self.x[self.dofmap])
        return self._vertices, self._vertices

    def _nodal_jacobian(self, nodes: npt.NDArray) -> npt.NDArray:
        """``J[c, g, t]`` of affine cells from their geometry nodes (c, nnodes, gdim)."""
        return np.swapaxes(nodes[:, self._unit, :] - nodes[:, :1, :], 1, 2)

    @property
    def axis_aligned(self) -> bool:
        """Whether every cell is an affine image of the reference box that is itself an
        axis-aligned box (one non-zero entry per row of J); computed once."""
        if not hasattr(self, "_axis_aligned"):
            aligned = False
            if self.affine:
                J = self.jacobian(np.arange(len(self.dofmap)), None)
                big = np.abs(J) > 1e-12 * np.abs(J).max(initial=1.0)
                aligned = bool(np.all(big.sum(axis=2) == 1))
            self._axis_aligned = aligned
        return self._axis_aligned

    # -- push forward -------------------------------------------------------------------------
    def _tabulate(self, nderiv: int, X: npt.NDArray) -> npt.NDArray:
        return self.element.tabulate(nderiv, np.ascontiguousarray(X, dtype=np.float64))[..., 0]

    def push_forward(self, cells: npt.NDArray[np.int32], X: npt.NDArray) -> npt.NDArray:
        """Physical coordinates ``x(X)`` of reference points ``X`` (n, tdim) in ``cells``."""
        if self.affine:
            return self.x0[cells] + np.einsum("ngt,nt->ng", self.jacobian(cells, X), X)
        phi = self._tabulate(0, X)[0]  # (n, ndofs)
        return np.einsum("nk,nkg->ng", phi, self.x[self.dofmap[cells]])

    def jacobian(self, cells: npt.NDArray[np.int32], X: npt.NDArray) -> npt.NDArray:
        """``J[n, g, t] = dx_g / dX_t`` at the points, shape (n, gdim, tdim)."""
        if self.affine:
            return self._nodal_jacobian(self.x[self.dofmap[cells]])
        dphi = self._tabulate(1, X)[1:]  # (tdim, n, ndofs)
        return np.einsum("tnk,nkg->ngt", dphi, self.x[self.dofmap[cells]])

    def inverse_jacobian(self, cells: npt.NDArray[np.int32], X: npt.NDArray) -> npt.NDArray:
        """``K = J^{-1}``, shape (n, tdim, gdim), so that ``grad N = dN/dX @ K``."""
        if self.affine:
            return self.K[cells]
        return np.linalg.inv(self.jacobian(cells, X))

    def detJ(self, cells: npt.NDArray[np.int32], X: npt.NDArray) -> npt.NDArray:
        return np.linalg.det(self.jacobian(cells, X))

    # -- pull back ----------------------------------------------------------------------------
    def pull_back(
        self, cells: npt.NDArray[np.int32], x: npt.NDArray, *, tol: float = 1e-12, max_it: int = 30
    ) -> npt.NDArray:
        """Reference coordinates of physical points ``x`` (n, gdim) with respect to ``cells``.

        Points outside a non-affine cell may not converge: their entries are NaN.
        """
        x = np.asarray(x, dtype=np.float64)[:, : self.gdim]
        if self.affine:
            return np.einsum("ntg,ng->nt", self.K[cells], x - self.x0[cells])
        nodes = self.x[self.dofmap[cells]]  # (n, ndofs, gdim)
        X = np.tile(basix.geometry(self.basix_cell).mean(axis=0), (len(cells), 1))
        active = np.arange(len(cells))
        for _ in range(max_it):
            if active.size == 0:
                break
            tab = self._tabulate(1, X[active])
            xa = np.einsum("nk,nkg->ng", tab[0], nodes[active])
            J = np.einsum("tnk,nkg->ngt", tab[1:], nodes[active])
            with np.errstate(all="ignore"):
                dX = np.linalg.solve(J, (x[active] - xa)[..., None])[..., 0]
            X[active] += dX
            step = np.linalg.norm(dX, axis=1)
            bad = ~np.isfinite(step) | (np.abs(X[active]).max(axis=1) > 1e3)
            X[active[bad]] = np.nan
            done = bad | (step < tol)
            active = active[~done]
        X[active] = np.nan  # not converged
        return X

    def contains(self, X: npt.NDArray, tol: float = 1e-10) -> npt.NDArray[np.bool_]:
        """Whether reference points lie in the reference cell (within ``tol``)."""
        with np.errstate(invalid="ignore"):
            inside = np.all(X >= -tol, axis=1)
            if self.cell_name in SIMPLICES:
                inside &= X.sum(axis=1) <= 1.0 + tol
            else:
                inside &= np.all(X <= 1.0 + tol, axis=1)
        return inside & np.all(np.isfinite(X), axis=1)

    def closest_points(self, cells: npt.NDArray[np.int32], x: npt.NDArray) -> npt.NDArray:
        """The closest point of each cell to the point ``x`` outside it (n, gdim): the nearest
        point of the cell's facets, taken as straight segments (2D) or triangles (3D; a
        quadrilateral face as two triangles)."""
        x = np.asarray(x, dtype=np.float64)[:, : self.gdim]
        verts = self.x[self.dofmap[cells]]  # (n, nodes, gdim); vertices first
        topo = basix.topology(self.basix_cell)[self.tdim - 1]
        best = np.full(len(x), np.inf)
        out = x.copy()
        for facet in topo:  # loop over the few facets of a cell, not over points
            tris = [facet] if len(facet) <= 3 else [[facet[0], facet[1], facet[3]], [facet[0], facet[2], facet[3]]]
            for tri in tris:
                y = _closest_on_simplex(verts[:, tri, :], x)
                dist = np.linalg.norm(y - x, axis=1)
                closer = dist < best
                best[closer], out[closer] = dist[closer], y[closer]
        return out

    def cell_volumes(self) -> npt.NDArray:
        """Volumes of all local cells (owned and ghost), by Gauss quadrature of ``|det J|``."""
        ncells = self.dofmap.shape[0]
        if self.affine:
            ref_volume = {1: 1.0, 2: 0.5, 3: 1.0 / 6.0}[self.tdim] if self.cell_name in SIMPLICES else 1.0
            return np.abs(self.detJ(np.arange(ncells), None)) * ref_volume
        deg = 2 * self.element.degree * self.tdim
        Xq, wq = basix.make_quadrature(self.basix_cell, deg)
        dphi = self._tabulate(1, Xq)[1:]  # (tdim, q, ndofs)
        J = np.einsum("tqk,ckg->cqgt", dphi, self.x[self.dofmap[:ncells]])
        return np.abs(np.linalg.det(J)) @ wq


def _closest_on_segment(a: npt.NDArray, b: npt.NDArray, x: npt.NDArray) -> npt.NDArray:
    ab = b - a
    t = np.einsum("nd,nd->n", x - a, ab) / np.maximum(np.einsum("nd,nd->n", ab, ab), 1e-300)
    return a + np.clip(t, 0.0, 1.0)[:, None] * ab


def _closest_on_simplex(S: npt.NDArray, x: npt.NDArray) -> npt.NDArray:
    """Closest points of vertices (n, 1), segments (n, 2) or triangles (n, 3) to ``x`` (n, d)."""
    k = S.shape[1]
    if k == 1:
        return S[:, 0]
    if k == 2:
        return _closest_on_segment(S[:, 0], S[:, 1], x)
    a, b, c = S[:, 0], S[:, 1], S[:, 2]
    E = np.stack([b - a, c - a], axis=2)  # (n, d, 2)
    lam = np.linalg.solve(np.swapaxes(E, 1, 2) @ E, (np.swapaxes(E, 1, 2) @ (x - a)[:, :, None]))[:, :, 0]
    y = a + np.einsum("ndk,nk->nd", E, lam)
    inside = (lam >= 0).all(axis=1) & (lam.sum(axis=1) <= 1)
    best = np.where(inside, 0.0, np.inf)
    best_y = np.where(inside[:, None], y, x)
    for p, q in ((a, b), (b, c), (c, a)):
        z = _closest_on_segment(p, q, x)
        dist = np.linalg.norm(z - x, axis=1)
        closer = ~inside & (dist < best)
        best[closer], best_y[closer] = dist[closer], z[closer]
    return best_y
