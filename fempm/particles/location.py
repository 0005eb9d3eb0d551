"""Locate points in the owned cells of a DOLFINx mesh and pull them back to the reference cell.

Candidates come from a bounding-box tree over the *owned* cells only (a ghost cell would count a
particle twice in P2G); each candidate is tested with the vectorized pull-back of
:class:`fempm.meshes.geometry.CellGeometry`, which also gives the reference coordinates. Relocation
tests each point's previous cell first, then the cells sharing a vertex with it
(:meth:`CellLocator.locate_near`), and searches the tree only for the points found in neither;
the tree is built on its first search.
"""

from __future__ import annotations

import dolfinx
import dolfinx.geometry
import numpy as np
import numpy.typing as npt

from fempm.kernels import shape as shape_kernels
from fempm.kernels.bundles import Star
from fempm.meshes.geometry import CellGeometry
from fempm.particles.cell_bins import CellBins

__all__ = ["LOCATE_CHUNK", "CellLocator", "OutsideMeshError", "as_points3", "lowest_finding_rank", "outside_message"]

#: points located at a time (bounds the memory of the candidate lists)
LOCATE_CHUNK = 65536


class OutsideMeshError(ValueError):
    """Particles lie outside the mesh (no owned cell of any rank contains them)."""


def outside_message(count: int, examples: npt.NDArray) -> str:
    pts = "; ".join(np.array2string(p, precision=6, separator=", ") for p in examples[:5])
    return (
        f"{count} particle(s) lie outside the mesh, e.g. at {pts}. "
        "Pass outside='remove' to drop them (the number removed is reported)."
    )


def as_points3(x: npt.NDArray) -> npt.NDArray[np.float64]:
    """Points padded to the 3 columns DOLFINx geometry routines expect."""
    x = np.asarray(x, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    out = np.zeros((len(x), 3))
    out[:, : x.shape[1]] = x
    return out


class CellLocator:
    """Point location in owned cells, with the reference coordinates of each point in its cell.

    Args:
        mesh: The background mesh.
        tol: The tolerance on the reference coordinates for a point to count as inside a cell.
        ghosts: Also search the rank's ghost cells (for the sample points of particle domains,
            whose contributions go to ghost dofs and are summed to their owners; particles
            themselves are located in owned cells only).
    """

    def __init__(self, mesh: dolfinx.mesh.Mesh, *, tol: float = 1e-10, ghosts: bool = False):
        self.mesh = mesh
        self.tol = tol
        self.geometry = CellGeometry(mesh)
        tdim = mesh.topology.dim
        imap = mesh.topology.index_map(tdim)
        nlocal = imap.size_local + (imap.num_ghosts if ghosts else 0)
        self._entities = np.arange(nlocal, dtype=np.int32)
        self._tree = None
        self._star: tuple | None = None
        self._vertex_ranks: tuple | None = None
        self._global_tree = None
        self._midpoint_tree = None
        self._cell_bins = None

    @property
    def compiled(self) -> bool:
        """Whether the compiled pull-backs of :mod:`fempm.kernels.shape` serve this mesh (affine
        or multilinear cells, numba)."""
        return shape_kernels.AVAILABLE and self.geometry.kernel_cell is not None

    @property
    def num_cells(self) -> int:
        """The number of cells searched: the owned ones (and the ghosts for a locator with
        ``ghosts``), numbered from 0."""
        return len(self._entities)

    @property
    def tree(self):
        """Bounding-box tree of the searched cells, made on first use (local to the rank): a
        mesh-sized structure (0.1 kB a cell in 2D) that runs which only relocate particles to
        neighbouring cells (:meth:`locate_near`) never build."""
        if self._tree is None:
            extent = np.ptp(self.geometry.x, axis=0).max() if len(self.geometry.x) else 1.0
            self._tree = dolfinx.geometry.bb_tree(self.mesh, self.geometry.tdim, entities=self._entities,
                                                  padding=1e-8 * extent)
        return self._tree

    def release_tree(self) -> None:
        """Free the bounding-box tree (and the trees made from it); the next search makes it
        again."""
        self._tree = self._global_tree = self._midpoint_tree = None

    @property
    def global_tree(self):
        """Tree of the ranks' bounding boxes (collective on first use)."""
        if self._global_tree is None:
            self._global_tree = self.tree.create_global_tree(self.mesh.comm)
        return self._global_tree

    def closest(self, x: npt.NDArray) -> tuple[npt.NDArray[np.int32], npt.NDArray]:
        """For points outside the located cells: the closest cell (owned, or with ``ghosts``
        also ghost) and the closest point of it (n, gdim), the point clamped onto the mesh."""
        if self._midpoint_tree is None:
            self._midpoint_tree = dolfinx.geometry.create_midpoint_tree(self.mesh, self.geometry.tdim, self._entities)
        if len(x) == 0:
            return np.zeros(0, dtype=np.int32), np.zeros((0, self.geometry.gdim))
        cells = np.asarray(dolfinx.geometry.compute_closest_entity(self.tree, self._midpoint_tree, self.mesh,
                                                                   as_points3(x)), dtype=np.int32)
        return cells, self.geometry.closest_points(cells, x)

    def closest_on_mesh(self, x: npt.NDArray) -> npt.NDArray:
        """The closest point of the whole mesh (every rank's cells of this locator, owned cells
        for a locator without ghosts) to each point of ``x`` (n, gdim), the same on any number
        of ranks. Collective; ``x`` is gathered on every rank, so keep it small."""
        comm = self.mesh.comm
        if comm.size == 1:
            return self.closest(x)[1]
        parts = comm.allgather(np.asarray(x, dtype=np.float64).reshape(-1, self.geometry.gdim))
        allx = np.concatenate(parts)
        _, y = self.closest(allx)
        dist = np.linalg.norm(y - allx, axis=1) if len(allx) else np.zeros(0)
        dists, ys = np.array(comm.allgather(dist)), np.array(comm.allgather(y))  # (ranks, m), (ranks, m, d)
        best = np.argmin(dists, axis=0)  # ties: the lowest rank
        start = sum(len(p) for p in parts[: comm.rank])
        return ys[best, np.arange(len(allx))][start : start + len(parts[comm.rank])]

    @property
    def cell_bins(self):
        """Bounding boxes of the *owned* cells in a uniform bin grid (:class:`fempm.particles.cell_bins.CellBins`),
        made on first use."""
        if self._cell_bins is None:
            owned = self.mesh.topology.index_map(self.geometry.tdim).size_local
            self._cell_bins = CellBins(self.geometry, np.arange(owned, dtype=np.int32))
        return self._cell_bins

    def candidate_ranks(self, x: npt.NDArray) -> tuple[npt.NDArray, npt.NDArray]:
        """Pairs (point index, rank) whose rank's bounding box holds the point."""
        adj = dolfinx.geometry.compute_collisions_points(self.global_tree, as_points3(x))
        counts = np.diff(adj.offsets)
        return np.repeat(np.arange(len(x)), counts), np.asarray(adj.array)

    def send_to_candidates(self, x: npt.NDArray) -> tuple[list[npt.NDArray], list[npt.NDArray]]:
        """Send each point of ``x`` to every *other* rank whose bounding box holds it
        (collective, one ``alltoall``): returns, per rank r, the indices into ``x`` sent to r
        and the points received from r."""
        comm = self.mesh.comm
        rank, size = comm.rank, comm.size
        pidx, ranks = self.candidate_ranks(x)
        other = ranks != rank
        pidx, ranks = pidx[other], ranks[other]
        order = np.argsort(ranks, kind="stable")
        pidx, ranks = pidx[order], ranks[order]
        bounds = np.searchsorted(ranks, np.arange(size + 1))
        sent = [pidx[bounds[r] : bounds[r + 1]] for r in range(size)]
        return sent, comm.alltoall([np.ascontiguousarray(x[i]) for i in sent])

    def locate(self, x: npt.NDArray) -> tuple[npt.NDArray[np.int32], npt.NDArray]:
        """Owned (or, with ``ghosts``, local) cell (``-1`` if none) and reference coordinates of
        each point of ``x``; in chunks of :data:`LOCATE_CHUNK` points, so that the candidate
        lists stay small."""
        n = len(x)
        tdim = self.geometry.tdim
        cells = np.full(n, -1, dtype=np.int32)
        X = np.full((n, tdim), np.nan)
        for start in range(0, n, LOCATE_CHUNK):  # a loop over chunks, not over points
            part = slice(start, min(start + LOCATE_CHUNK, n))
            cells[part], X[part] = self._locate(np.asarray(x[part]))
        return cells, X

    def _locate(self, x: npt.NDArray) -> tuple[npt.NDArray[np.int32], npt.NDArray]:
        n = len(x)
        geo = self.geometry
        cells = np.full(n, -1, dtype=np.int32)
        X = np.full((n, geo.tdim), np.nan)
        adj = dolfinx.geometry.compute_collisions_points(self.tree, as_points3(x))
        cand = np.asarray(adj.array, dtype=np.int32)
        pidx = np.repeat(np.arange(n), np.diff(adj.offsets))
        if cand.size == 0:
            return cells, X
        if self.compiled:
            Xc, inside = shape_kernels.cell_pull_back(cand, x[pidx], *geo.kernel_geometry, geo.kernel_cell, self.tol)
        else:
            Xc = geo.pull_back(cand, x[pidx])
            inside = geo.contains(Xc, self.tol)
        hit_p, first = np.unique(pidx[inside], return_index=True)
        hits = np.flatnonzero(inside)[first]
        cells[hit_p] = cand[hits]
        X[hit_p] = Xc[hits]
        return cells, X

    def vertex_star(self) -> Star:
        """(cell -> vertices (cells, vertices per cell), vertex -> cells offsets and cells, the
        number of owned cells) as the kernels take it (:class:`fempm.kernels.bundles.Star`): what
        :meth:`locate_near` searches, built once."""
        if self._star is None:
            geo = self.geometry
            top = self.mesh.topology
            top.create_connectivity(geo.tdim, 0)
            top.create_connectivity(0, geo.tdim)
            c2v, v2c = top.connectivity(geo.tdim, 0), top.connectivity(0, geo.tdim)
            self._star = Star(np.ascontiguousarray(c2v.array.reshape(-1, len(c2v.links(0)))), v2c.offsets,
                              v2c.array, len(self._entities))
        return self._star

    def vertex_ranks(self) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int32]]:
        """For each local vertex, the other ranks that hold it (owner and ghosting ranks as far
        as this rank knows them: an owned vertex's ghosting ranks, a ghost vertex's owner), as
        CSR (offsets, ranks); made once."""
        if self._vertex_ranks is None:
            vmap = self.mesh.topology.index_map(0)
            n, ng = vmap.size_local, vmap.num_ghosts
            dest = vmap.index_to_dest_ranks(0)  # the argument: a message tag
            index = np.concatenate([np.repeat(np.arange(len(dest.offsets) - 1), np.diff(dest.offsets)),
                                    np.arange(n, n + ng)])
            ranks = np.concatenate([np.asarray(dest.array), np.asarray(vmap.owners)]).astype(np.int64)
            pairs = np.unique(index * self.mesh.comm.size + ranks)
            offsets = np.searchsorted(pairs // self.mesh.comm.size, np.arange(n + ng + 1)).astype(np.int64)
            self._vertex_ranks = (offsets, (pairs % self.mesh.comm.size).astype(np.int32))
        return self._vertex_ranks

    def locate_at_vertices(self, x: npt.NDArray, global_vertices: npt.NDArray[np.int64]) -> tuple[npt.NDArray[np.int32], npt.NDArray]:
        """The lowest-numbered searched cell holding one of the vertices ``global_vertices``
        (n, k; global numbers, those not held here ignored) that contains each point of ``x``
        (-1: none), and the reference coordinates there: where a particle that left a cell with
        these vertices on another rank can be (cells with straight edges, compiled)."""
        geo = self.geometry
        c2v, v_offsets, v_cells, owned = self.vertex_star()
        vmap = self.mesh.topology.index_map(0)
        local = vmap.global_to_local(np.ascontiguousarray(global_vertices, dtype=np.int64).ravel())
        local = np.asarray(local, dtype=np.int32).reshape(global_vertices.shape)
        return shape_kernels.vertex_star_pull_back(x, local, *geo.kernel_geometry, v_offsets, v_cells, owned,
                                                   geo.kernel_cell, self.tol)

    def locate_near(self, x: npt.NDArray, previous: npt.NDArray[np.int32], *,
                    ghosts: bool = False) -> tuple[npt.NDArray[np.int32], npt.NDArray]:
        """Like :meth:`locate` for points that left their ``previous`` owned cells: the cells
        sharing a vertex with the previous one are tested first (the lowest-numbered cell
        containing the point wins; cells with straight edges, compiled), the tree searches only for the
        points not found there. ``ghosts``: the ghost cells among those neighbours are tested
        too (after the owned ones: they are numbered after them), so that a particle moving to
        another rank's cell in the ghost layer is sent there without a tree search
        (:func:`fempm.particles.migration.migrate`); its cell is then at or above the owned count."""
        geo = self.geometry
        if not self.compiled or len(x) == 0:
            return self.locate(x)
        c2v, v_offsets, v_cells, owned = self.vertex_star()
        cells, X = shape_kernels.near_pull_back(np.asarray(previous, dtype=np.int32), np.ascontiguousarray(x),
                                                *geo.kernel_geometry, c2v, v_offsets, v_cells,
                                                len(c2v) if ghosts else owned, geo.kernel_cell, self.tol)
        miss = np.flatnonzero(cells < 0)
        if len(miss) and not ghosts:
            cells[miss], X[miss] = self.locate(np.asarray(x)[miss])
        return cells, X

    def relocate(
        self, x: npt.NDArray, cells: npt.NDArray[np.int32], *, ghosts: bool = False
    ) -> tuple[npt.NDArray[np.int32], npt.NDArray]:
        """Like :meth:`locate`, testing each point's previous owned cell first (``ghosts``: as
        in :meth:`locate_near`)."""
        cells = np.asarray(cells, dtype=np.int32)
        X = np.full((len(x), self.geometry.tdim), np.nan)
        new_cells = np.full(len(x), -1, dtype=np.int32)
        geo = self.geometry
        valid = np.flatnonzero(cells >= 0)
        if self.compiled:  # one compiled pass
            new_cells = cells.copy()
            X, stay = shape_kernels.cell_pull_back(cells, x, *geo.kernel_geometry, geo.kernel_cell, self.tol)
            new_cells[~stay] = -1
        elif valid.size:
            Xv = self.geometry.pull_back(cells[valid], np.asarray(x)[valid])
            stay = self.geometry.contains(Xv, self.tol)
            new_cells[valid[stay]] = cells[valid[stay]]
            X[valid[stay]] = Xv[stay]
        moved = np.flatnonzero(new_cells < 0)
        if moved.size:
            had = moved[cells[moved] >= 0]
            new_cells[had], X[had] = self.locate_near(np.asarray(x)[had], cells[had], ghosts=ghosts)
            fresh = moved[cells[moved] < 0]
            new_cells[fresh], X[fresh] = self.locate(np.asarray(x)[fresh])
        return new_cells, X


def lowest_finding_rank(sent: list[npt.NDArray], found: list[npt.NDArray[np.bool_]], m: int) -> npt.NDArray[np.int64]:
    """For ``m`` points sent to ranks (``sent[r]``: indices sent to rank r) and the ranks'
    answers (``found[r]``: which of them rank r holds), the lowest rank holding each point,
    or ``len(sent)`` where none does."""
    size = len(sent)
    owner = np.full(m, size, dtype=np.int64)
    for r in range(size):  # ascending: the lowest finding rank wins
        hit = sent[r][found[r]]
        free = owner[hit] == size
        owner[hit[free]] = r
    return owner
