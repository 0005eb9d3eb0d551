r"""Exact GIMP as sample points: the particle's box cut by the cells, in a compiled pass
(:class:`fempm.stepping.domain_grid.DomainGrid` drives it; :class:`fempm.transfer.box_average.BoxIntegrator`
is its reference).

For a degree-1 basis on affine simplices, and on cells that are axis-aligned boxes (intervals,
rectangles, bricks), the average of the basis over a piece :math:`P = \Omega_p \cap c` of the
particle's box is its value at the piece's centroid :math:`\bar y_P` (the basis is linear on a
simplex; on a box cell a product of one linear factor per axis, and a box piece's average of
such a product is the product of the factors' averages), and its gradient is constant on the
simplex or, on the box, each component is a product of the other axes' factors. So the exact
GIMP average

.. math::
    \langle N_i \rangle_p = \frac{1}{|\Omega_p \cap \Omega_h|} \sum_{c} |P_c|\, N_i(\bar y_{P_c}),
    \qquad
    \langle \nabla N_i \rangle_p = \frac{1}{|\Omega_p \cap \Omega_h|} \sum_{c} |P_c|\, \nabla N_i(\bar y_{P_c})

is a set of samples (one a cell the box meets: its piece's centroid, weight
:math:`|P_c| / |\Omega_p \cap \Omega_h|`), which the sample passes of :mod:`fempm.kernels.samples`
sum with ``grad_from_values``. The cells the box meets are found by a flood from the
particle's cell through the cells sharing a vertex whose bounding boxes overlap the box
(:func:`box_samples`; the last step's piece cells first: where their pieces cover the box,
no other cell meets it). A triangle's piece is the box's image in the reference triangle (a
parallelogram) clipped by the triangle's edges that cross it (Sutherland and Hodgman), its
area and centroid by the shoelace formula; a tetrahedron's piece is integrated over its faces
by the divergence theorem, :math:`|P| = \tfrac13 \oint_{\partial P} x \cdot n`,
:math:`\int_P x = \tfrac14 \oint_{\partial P} x\, (x \cdot n)`, the faces being the
tetrahedron's faces clipped by the box and the box's faces clipped by the tetrahedron; a box
cell's piece is the intersection of the two boxes.
"""

from __future__ import annotations

import functools

import numpy as np

from fempm.kernels.bundles import Star
from fempm.kernels.choice import INLINE
from fempm.kernels.shape import AVAILABLE

__all__ = ["box_samples"]

#: the most cells one box is searched over (the flood's visited list)
MAX_VISITED = 512
#: a box whose pieces in the last step's cells cover all but this fraction of it meets no other
#: cell (the cells do not overlap; the pieces' volumes sum to the box's to round-off)
COVERED = 1e-12


if AVAILABLE:
    from numba import njit

    from fempm.kernels.box_pieces import tetrahedron_piece, triangle_piece

    @njit(inline=INLINE)
    def box_piece(c, d, blo, bhi, x0, K, lo, hi, acc, cen):  # pragma: no cover - compiled
        """The volume of the part of box [lo, hi] in the axis-aligned box cell ``c``, its
        centroid's reference coordinates into ``cen`` (``acc``: a work array)."""
        vol = 1.0  # a box cell: the piece is a box
        for e in range(d):
            a = max(lo[e], blo[c, e])
            b = min(hi[e], bhi[c, e])
            vol *= max(b - a, 0.0)
            acc[e] = 0.5 * (a + b)
        for i in range(d):  # the centroid's reference coordinates
            t = 0.0
            for e in range(d):
                t += K[c, i, e] * (acc[e] - x0[c, e])
            cen[i] = t
        return vol


if AVAILABLE:
    @njit(inline=INLINE)
    def _record(npiece, c, vol, cen, piece_cell, piece_vol, piece_cen):  # pragma: no cover - compiled
        """Keep piece ``npiece`` (cell, volume, centroid); returns the count."""
        piece_cell[npiece], piece_vol[npiece] = c, vol
        for e in range(len(cen)):
            piece_cen[npiece, e] = cen[e]
        return npiece + 1

    @njit(inline=INLINE)
    def _enqueue(c, c2v, v_offsets, v_cells, num_cells, blo, bhi, lo, hi, visited, nvis):  # pragma: no cover
        """Append to ``visited`` the cells sharing a vertex with ``c`` whose bounding boxes
        overlap ``[lo, hi]`` and that it does not hold; returns (its length, whether it was
        full)."""
        crowded = False
        for a in range(c2v.shape[1]):
            v = c2v[c, a]
            for q in range(v_offsets[v], v_offsets[v + 1]):
                f = v_cells[q]
                if f >= num_cells:
                    continue
                overlaps = True
                for e in range(len(lo)):
                    if not (blo[f, e] < hi[e] and bhi[f, e] > lo[e]):
                        overlaps = False
                if not overlaps:
                    continue
                seen = False
                for r in range(nvis):
                    if visited[r] == f:
                        seen = True
                        break
                if not seen:
                    if nvis == MAX_VISITED:
                        crowded = True
                    else:
                        visited[nvis] = f
                        nvis += 1
        return nvis, crowded

    @njit(inline=INLINE)
    def _guesses(p, sc, w, num_cells, guess):  # pragma: no cover - compiled
        """The cells of particle ``p``'s samples of weight into ``guess``; returns their count."""
        ng = 0
        for r in range(sc.shape[1]):
            c = sc[p, r]
            if w[p, r] > 0.0 and c >= 0 and c < num_cells:
                guess[ng] = c
                ng += 1
        return ng

    @njit(inline=INLINE)
    def _store(p, npiece, piece_cell, piece_vol, piece_cen, sc, Y, w):  # pragma: no cover - compiled
        """Particle ``p``'s samples: its pieces by ascending cell (the same order and sums
        whether found from the last step's cells or by the flood: a resumed run repeats the
        steps bit for bit), weights their shares of the covered volume, then unused ones of no
        weight in the first piece's cell."""
        Q, d = sc.shape[1], Y.shape[1]
        for r in range(1, npiece):  # insertion sort of the few pieces
            j = r
            while j > 0 and piece_cell[j - 1] > piece_cell[j]:
                piece_cell[j - 1], piece_cell[j] = piece_cell[j], piece_cell[j - 1]
                piece_vol[j - 1], piece_vol[j] = piece_vol[j], piece_vol[j - 1]
                for i in range(d):
                    piece_cen[j - 1, i], piece_cen[j, i] = piece_cen[j, i], piece_cen[j - 1, i]
                j -= 1
        covered = 0.0
        for r in range(npiece):
            covered += piece_vol[r]
        for r in range(min(npiece, Q)):
            sc[p, r] = piece_cell[r]
            w[p, r] = piece_vol[r] / covered
            for i in range(d):
                Y[p * Q + r, i] = piece_cen[r, i]
        for r in range(npiece, Q):
            sc[p, r] = sc[p, 0]
            w[p, r] = 0.0
            for i in range(d):
                Y[p * Q + r, i] = Y[p * Q, i]


@functools.cache
def _kernel(d: int, simplex: bool):
    """The sample kernel of cells of dimension ``d``: triangles, tetrahedra, or (``simplex``
    False, and intervals) axis-aligned boxes."""
    TRIANGLE = simplex and d == 2
    TETRAHEDRON = simplex and d == 3

    @njit(cache=True, error_model="numpy")
    def kernel(x, ell, cells, verts, bounds, star, frontier, x0, K, guessed, out):  # pragma: no cover - compiled
        blo, bhi = bounds
        c2v, v_offsets, v_cells, num_cells = star
        sc, Y, w = out
        n = len(cells)
        Q = sc.shape[1]
        lo, hi, cen = np.empty(d), np.empty(d), np.empty(d)
        P, acc = np.empty((32, d)), np.empty(4)
        visited = np.empty(MAX_VISITED, np.int32)
        guess = np.empty(Q, np.int32)
        piece_cell = np.empty(MAX_VISITED, np.int32)
        piece_vol = np.empty(MAX_VISITED)
        piece_cen = np.empty((MAX_VISITED, d))
        needed, reaching, failed = 0, 0, 0
        for p in range(n):
            box = 1.0
            for e in range(d):
                lo[e] = x[p, e] - ell[p, e]
                hi[e] = x[p, e] + ell[p, e]
                box *= hi[e] - lo[e]
            # the cells of the last step's pieces: when they cover the box, they are all it meets
            ng = _guesses(p, sc, w, num_cells, guess) if guessed else 0
            npiece, covered, ghost = 0, 0.0, False
            for r in range(ng):
                vol = (triangle_piece(x, p, ell, x0, K, guess[r], P, cen) if TRIANGLE else
                       tetrahedron_piece(verts[guess[r]], x0, K, guess[r], lo, hi, P, acc, cen) if TETRAHEDRON else
                       box_piece(guess[r], d, blo, bhi, x0, K, lo, hi, acc, cen))
                if vol > 0.0:
                    npiece = _record(npiece, guess[r], vol, cen, piece_cell, piece_vol, piece_cen)
                    covered += vol
            crowded = False
            if not covered >= box * (1.0 - COVERED):  # a flood from the particle's cell
                visited[0] = cells[p]
                nvis, head, npiece, covered = 1, 0, 0, 0.0
                while head < nvis:
                    c = visited[head]
                    head += 1
                    vol = (triangle_piece(x, p, ell, x0, K, c, P, cen) if TRIANGLE else
                       tetrahedron_piece(verts[c], x0, K, c, lo, hi, P, acc, cen) if TETRAHEDRON else
                       box_piece(c, d, blo, bhi, x0, K, lo, hi, acc, cen))
                    if not vol > 0.0:
                        continue
                    npiece = _record(npiece, c, vol, cen, piece_cell, piece_vol, piece_cen)
                    covered += vol
                    ghost = ghost or frontier[c]
                    if covered >= box * (1.0 - COVERED):
                        break  # no other cell meets the box
                    nvis, full = _enqueue(c, c2v, v_offsets, v_cells, num_cells, blo, bhi, lo, hi, visited, nvis)
                    crowded = crowded or full
            needed = max(needed, npiece)
            if crowded or npiece == 0:
                failed += 1
                continue
            if covered < box * (1.0 - COVERED) and ghost:
                reaching += 1  # part of the box may lie in cells this rank does not have
            _store(p, npiece, piece_cell, piece_vol, piece_cen, sc, Y, w)
        return needed, reaching, failed

    return kernel


def box_samples(x, ell, cells, cell_type: tuple[int, bool], verts, bounds: tuple, star: Star, frontier, x0, K,
                out, guessed: bool = False):
    r"""The exact GIMP samples of boxes ``[x - ell, x + ell]`` (n, d) of particles in ``cells``
    (see the module).

    Args:
        x: Box centres (n, d).
        ell: Half-widths (n, d), positive.
        cells: The particles' cells (n,), which hold their centres.
        cell_type: (dimension, simplex) of the cells; intervals and non-simplices are taken as
            axis-aligned boxes.
        verts: The simplices' vertices (cells, d + 1, d) (unused for boxes).
        bounds: (lower, upper): the cells' bounding boxes (cells, d) each.
        star: Cell -> vertices, vertex -> cells offsets and cells, and the number of cells
            searched (:meth:`fempm.particles.location.CellLocator.vertex_star`).
        frontier: Per cell (bool), whether it has a vertex that another rank's cells share (an
            uncovered box with a piece in such a cell may reach cells this rank does not have;
            one whose pieces avoid them is cut by the mesh's boundary). All False on one rank.
        x0, K: The affine map of each cell (:attr:`fempm.meshes.geometry.CellGeometry.kernel_geometry`).
        out: (cells (n, Q) int32, reference coordinates (n Q, d), weights (n, Q)) to fill: the
            pieces of a box first, the other samples of no weight.
        guessed: Whether ``out`` holds samples of the particles already (the last step's):
            the cells of a particle's pieces there are searched first, and when the box's pieces
            in them cover it, no other cell is (a guess only: the rows of other particles, or
            none, cost a search).

    Returns:
        The most pieces of one box (more than ``Q``: call again with a larger ``Q``), the number
        of boxes not wholly covered with a piece in a ``frontier`` cell (part of them may lie
        in cells this rank does not have), and the number of boxes left without samples (that met
        more than :data:`MAX_VISITED` cells, or none).
    """
    d, simplex = cell_type
    sc, Y, w = out
    needed, reaching, failed = _kernel(d, simplex)(x, np.ascontiguousarray(ell), cells, verts, tuple(bounds),
                                                    star, frontier, x0, K, bool(guessed), (sc, Y, w))
    return int(needed), int(reaching), int(failed)
