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
(:func:`box_samples`); a simplex is cut by the box's :math:`2d` half-spaces one after the
other into simplices (:func:`clip_simplex`, the arithmetic of
:func:`fempm.transfer.box_average.clip_simplices`), a box cell by taking the intersection of
the two boxes.
"""

from __future__ import annotations

import functools

import numpy as np

from fempm.kernels.shape import AVAILABLE

__all__ = ["box_samples", "clip_simplex", "piece_capacity"]

#: the most cells one box is searched over (the flood's visited list)
MAX_VISITED = 512
#: a box whose pieces in the last step's cells cover all but this fraction of it meets no other
#: cell (the cells do not overlap; the pieces' volumes sum to the box's to round-off)
COVERED = 1e-12


def piece_capacity(d: int) -> int:
    """The most simplices a simplex of dimension ``d`` is cut into by a box's :math:`2d` planes
    (each plane keeps a simplex whole, or cuts it into one, two (2D) or three (3D) simplices)."""
    return {1: 1, 2: 2**4, 3: 3**6}[d]


if AVAILABLE:
    from numba import njit

    @njit(cache=True, error_model="numpy")
    def _clip(S, lo, hi, A, B, moment, s, order, V, E, P):  # pragma: no cover - compiled
        """:func:`clip_simplex` with its work arrays: ``s``, ``order`` (d + 1,), ``V``
        (d + 1, d), ``E`` (d, d), ``P`` (6, d)."""
        k, d = S.shape
        A[0] = S
        na = 1
        for a in range(d):
            for side in (-1.0, 1.0):
                bound = lo[a] if side < 0.0 else hi[a]
                nb = 0
                for m in range(na):
                    nin = 0
                    for v in range(k):
                        s[v] = side * (A[m, v, a] - bound)
                        if s[v] <= 0.0:
                            nin += 1
                    if nin == k:
                        B[nb] = A[m]
                        nb += 1
                        continue
                    if nin == 0:
                        continue
                    j = 0
                    for v in range(k):  # the inside vertices first, in their order
                        if s[v] <= 0.0:
                            order[j] = v
                            j += 1
                    for v in range(k):
                        if s[v] > 0.0:
                            order[j] = v
                            j += 1
                    for v in range(k):
                        V[v] = A[m, order[v]]
                    nb = _cut(V, s, order, nin, d, B, nb, P)
                A, B = B, A
                na = nb
        volume = 0.0
        for e in range(d):
            moment[e] = 0.0
        factorial = 1.0
        for e in range(2, d + 1):
            factorial *= e
        for m in range(na):
            for r in range(d):
                for e in range(d):
                    E[r, e] = A[m, r + 1, e] - A[m, 0, e]
            vol = abs(_det(E, d)) / factorial
            volume += vol
            for e in range(d):
                c = 0.0
                for v in range(k):
                    c += A[m, v, e]
                moment[e] += vol * c / k
        return volume

    @njit(inline="always")
    def _point(V, s, order, i, o, out, row):  # pragma: no cover - compiled
        """``out[row]``: where the edge (i, o) of the ordered simplex ``V`` crosses the plane."""
        si, so = s[order[i]], s[order[o]]
        t = si / (si - so)
        for e in range(V.shape[1]):
            out[row, e] = V[i, e] + t * (V[o, e] - V[i, e])

    @njit(inline="always")
    def _cut(V, s, order, j, d, B, nb, P):  # pragma: no cover - compiled
        """Append to ``B`` the simplices of ``V`` (its first ``j`` vertices inside the plane)
        inside it (:func:`fempm.transfer.box_average._pieces`; ``P`` (6, d): room for the
        crossing points); returns the new count."""
        if j == 1:
            B[nb, 0] = V[0]
            for o in range(1, d + 1):
                _point(V, s, order, 0, o, B[nb], o)
            return nb + 1
        if d == 2:  # the quadrilateral v0 v1 p12 p02
            _point(V, s, order, 1, 2, P, 0)
            _point(V, s, order, 0, 2, P, 1)
            B[nb, 0] = V[0]
            B[nb, 1] = V[1]
            B[nb, 2] = P[0]
            B[nb + 1, 0] = V[0]
            B[nb + 1, 1] = P[0]
            B[nb + 1, 2] = P[1]
            return nb + 2
        # d = 3: the prism a0 a1 a2 - b0 b1 b2, rows 0-2 and 3-5 of P
        if j == 2:  # (v0, p02, p03) - (v1, p12, p13)
            P[0] = V[0]
            _point(V, s, order, 0, 2, P, 1)
            _point(V, s, order, 0, 3, P, 2)
            P[3] = V[1]
            _point(V, s, order, 1, 2, P, 4)
            _point(V, s, order, 1, 3, P, 5)
        else:  # (v0, v1, v2) - (p03, p13, p23)
            for v in range(3):
                P[v] = V[v]
            _point(V, s, order, 0, 3, P, 3)
            _point(V, s, order, 1, 3, P, 4)
            _point(V, s, order, 2, 3, P, 5)
        for t in range(3):  # (a0 a1 a2 b0), (a1 a2 b0 b1), (a2 b0 b1 b2)
            for v in range(4):
                B[nb + t, v] = P[t + v]
        return nb + 3

    @njit(inline="always")
    def _holds_box(x0, K, c, lo, hi, d):  # pragma: no cover - compiled
        """Whether the simplex ``c`` (``x = x0 + K^-1 X``) holds every corner of ``[lo, hi]``."""
        for corner in range(2**d):
            s = 0.0
            for i in range(d):
                t = 0.0
                for e in range(d):
                    t += K[c, i, e] * ((hi[e] if (corner >> e) & 1 else lo[e]) - x0[c, e])
                if t < 0.0:
                    return False
                s += t
            if s > 1.0:
                return False
        return True

    @njit(inline="always")
    def _det(E, d):  # pragma: no cover - compiled
        if d == 1:
            return E[0, 0]
        if d == 2:
            return E[0, 0] * E[1, 1] - E[0, 1] * E[1, 0]
        return (E[0, 0] * (E[1, 1] * E[2, 2] - E[1, 2] * E[2, 1]) - E[0, 1] * (E[1, 0] * E[2, 2] - E[1, 2] * E[2, 0])
                + E[0, 2] * (E[1, 0] * E[2, 1] - E[1, 1] * E[2, 0]))


def clip_simplex(S, lo, hi, A, B, moment) -> float:
    r"""The volume of the part of simplex ``S`` (d + 1, d) inside the box ``[lo, hi]``, and its
    first moment :math:`\int x` into ``moment`` (d,); ``A`` and ``B`` are work arrays
    (:func:`piece_capacity` (d), d + 1, d)."""
    k, d = S.shape
    return _clip(S, lo, hi, A, B, moment, np.empty(k), np.empty(k, np.int64), np.empty((k, d)), np.empty((d, d)),
                 np.empty((6, d)))


if AVAILABLE:
    @njit(inline="always")
    def _clip_polygon(P, src, n, f0, f1, f2, dst):  # pragma: no cover - compiled
        """The part of the polygon in rows ``src`` to ``src + n`` of ``P`` where
        ``f0 + f1 X_0 + f2 X_1 >= 0``, into the rows from ``dst``; returns its vertex count
        (Sutherland and Hodgman)."""
        m = 0
        j = src + n - 1
        fj = f0 + f1 * P[j, 0] + f2 * P[j, 1]
        for i in range(src, src + n):
            fi = f0 + f1 * P[i, 0] + f2 * P[i, 1]
            if (fi >= 0.0) != (fj >= 0.0):
                t = fj / (fj - fi)
                P[dst + m, 0] = P[j, 0] + t * (P[i, 0] - P[j, 0])
                P[dst + m, 1] = P[j, 1] + t * (P[i, 1] - P[j, 1])
                m += 1
            if fi >= 0.0:
                P[dst + m, 0] = P[i, 0]
                P[dst + m, 1] = P[i, 1]
                m += 1
            j, fj = i, fi
        return m

    @njit(inline="always")
    def _triangle_piece(x, p, ell, x0, K, c, P, cen):  # pragma: no cover - compiled
        r"""The area of the part of particle ``p``'s box in triangle ``c`` and its centroid's
        reference coordinates ``cen``: the box mapped to the reference triangle (a
        parallelogram) clipped by :math:`X_0 \ge 0`, :math:`X_1 \ge 0`, :math:`X_0 + X_1 \le 1`
        where it crosses them; the area times :math:`|\det J|` (``P`` (16, 2): room for the
        polygons)."""
        u0, u1 = x[p, 0] - x0[c, 0], x[p, 1] - x0[c, 1]
        X0 = K[c, 0, 0] * u0 + K[c, 0, 1] * u1
        X1 = K[c, 1, 0] * u0 + K[c, 1, 1] * u1
        a00, a01 = K[c, 0, 0] * ell[p, 0], K[c, 0, 1] * ell[p, 1]  # the half-edges, mapped
        a10, a11 = K[c, 1, 0] * ell[p, 0], K[c, 1, 1] * ell[p, 1]
        r0, r1, r2 = abs(a00) + abs(a01), abs(a10) + abs(a11), abs(a00 + a10) + abs(a01 + a11)
        L = 1.0 - X0 - X1
        if X0 + r0 <= 0.0 or X1 + r1 <= 0.0 or L + r2 <= 0.0:
            return 0.0  # apart
        detK = abs(K[c, 0, 0] * K[c, 1, 1] - K[c, 0, 1] * K[c, 1, 0])
        if X0 - r0 >= 0.0 and X1 - r1 >= 0.0 and L - r2 >= 0.0:  # inside
            cen[0], cen[1] = X0, X1
            return 4.0 * abs(a00 * a11 - a01 * a10) / detK
        n, at = 4, 0
        for k in range(4):  # the corners in turn around the box
            s0 = -1.0 if k == 0 or k == 3 else 1.0
            s1 = -1.0 if k < 2 else 1.0
            P[k, 0] = X0 + s0 * a00 + s1 * a01
            P[k, 1] = X1 + s0 * a10 + s1 * a11
        if X0 - r0 < 0.0:
            n = _clip_polygon(P, at, n, 0.0, 1.0, 0.0, 8 - at)
            at = 8 - at
        if X1 - r1 < 0.0:
            n = _clip_polygon(P, at, n, 0.0, 0.0, 1.0, 8 - at)
            at = 8 - at
        if L - r2 < 0.0:
            n = _clip_polygon(P, at, n, 1.0, -1.0, -1.0, 8 - at)
            at = 8 - at
        area, c0, c1 = 0.0, 0.0, 0.0
        for i in range(at, at + n):  # the shoelace formula about the first vertex
            j = i + 1 if i + 1 < at + n else at
            ax, ay = P[i, 0] - P[at, 0], P[i, 1] - P[at, 1]
            bx, by = P[j, 0] - P[at, 0], P[j, 1] - P[at, 1]
            cross = ax * by - bx * ay
            area += cross
            c0 += (ax + bx) * cross
            c1 += (ay + by) * cross
        if area == 0.0:
            return 0.0
        cen[0] = P[at, 0] + c0 / (3.0 * area)
        cen[1] = P[at, 1] + c1 / (3.0 * area)
        return 0.5 * abs(area) / detK


@functools.cache
def _kernel(d: int, simplex: bool):
    """The sample kernel of cells of dimension ``d``: triangles clipped in their reference
    coordinates, tetrahedra cut by :func:`clip_simplex`, or (``simplex`` False, and intervals)
    axis-aligned boxes."""
    BOX = not simplex or d == 1
    TRIANGLE = simplex and d == 2
    CAP = piece_capacity(d)

    @njit(inline="always")
    def piece(x, p, ell, c, verts, blo, bhi, x0, K, lo, hi, box, first, cen, A, B, moment, s, order, V, E,
              P):  # pragma: no cover
        """The volume of the part of box ``p`` in cell ``c``, its centroid's reference
        coordinates into ``cen`` (the others: work arrays)."""
        if TRIANGLE:
            return _triangle_piece(x, p, ell, x0, K, c, P, cen)
        if BOX:
            vol = 1.0
            for e in range(d):
                a = max(lo[e], blo[c, e])
                b = min(hi[e], bhi[c, e])
                vol *= max(b - a, 0.0)
                moment[e] = 0.5 * (a + b)
        elif first and _holds_box(x0, K, c, lo, hi, d):  # the box lies in the particle's cell
            vol = box
            for e in range(d):
                moment[e] = x[p, e]
        else:
            vol = _clip(verts[c], lo, hi, A, B, moment, s, order, V, E, P)
            if vol > 0.0:
                for e in range(d):
                    moment[e] /= vol
        for i in range(d):  # the centroid's reference coordinates
            t = 0.0
            for e in range(d):
                t += K[c, i, e] * (moment[e] - x0[c, e])
            cen[i] = t
        return vol

    @njit(cache=True, error_model="numpy")
    def kernel(x, ell, cells, verts, blo, bhi, c2v, v_offsets, v_cells, num_cells, num_owned, x0, K, guessed, sc, Y,
               w):  # pragma: no cover - compiled
        n = len(cells)
        Q = sc.shape[1]
        lo, hi, cen = np.empty(d), np.empty(d), np.empty(d)
        A, B, moment = np.empty((CAP, d + 1, d)), np.empty((CAP, d + 1, d)), np.empty(d)
        s, order, V, E = np.empty(d + 1), np.empty(d + 1, np.int64), np.empty((d + 1, d)), np.empty((d, d))
        P = np.empty((16, d))
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
            ng = 0
            if guessed:
                for r in range(Q):
                    c = sc[p, r]
                    if w[p, r] > 0.0 and c >= 0 and c < num_cells:
                        guess[ng] = c
                        ng += 1
            npiece, covered, ghost = 0, 0.0, False
            for r in range(ng):
                c = guess[r]
                vol = piece(x, p, ell, c, verts, blo, bhi, x0, K, lo, hi, box, False, cen, A, B, moment, s, order, V, E, P)
                if vol > 0.0:
                    piece_cell[npiece], piece_vol[npiece] = c, vol
                    for e in range(d):
                        piece_cen[npiece, e] = cen[e]
                    npiece += 1
                    covered += vol
            crowded = False
            if not covered >= box * (1.0 - COVERED):  # a flood from the particle's cell
                visited[0] = cells[p]
                nvis, head, npiece, covered = 1, 0, 0, 0.0
                while head < nvis:
                    c = visited[head]
                    head += 1
                    vol = piece(x, p, ell, c, verts, blo, bhi, x0, K, lo, hi, box, head == 1, cen, A, B, moment, s, order, V, E, P)
                    if not vol > 0.0:
                        continue
                    piece_cell[npiece], piece_vol[npiece] = c, vol
                    for e in range(d):
                        piece_cen[npiece, e] = cen[e]
                    npiece += 1
                    covered += vol
                    ghost = ghost or c >= num_owned
                    if covered >= box * (1.0 - COVERED):
                        break  # no other cell meets the box
                    for a in range(c2v.shape[1]):  # the cells sharing a vertex whose bounding boxes overlap
                        v = c2v[c, a]
                        for q in range(v_offsets[v], v_offsets[v + 1]):
                            f = v_cells[q]
                            if f >= num_cells:
                                continue
                            overlaps = True
                            for e in range(d):
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
            needed = max(needed, npiece)
            if crowded or npiece == 0:
                failed += 1
                continue
            if covered < box * (1.0 - COVERED) and ghost:
                reaching += 1  # part of the box may lie beyond this rank's ghost cells
            for r in range(min(npiece, Q)):
                sc[p, r] = piece_cell[r]
                w[p, r] = piece_vol[r] / covered
                for i in range(d):
                    Y[p * Q + r, i] = piece_cen[r, i]
            for r in range(npiece, Q):  # unused: no weight, in the first piece's cell
                sc[p, r] = sc[p, 0]
                w[p, r] = 0.0
                for i in range(d):
                    Y[p * Q + r, i] = Y[p * Q, i]
        return needed, reaching, failed

    return kernel


def box_samples(x, ell, cells, cell_type: tuple[int, bool], verts, blo, bhi, star: tuple, num_owned: int, x0, K,
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
        blo, bhi: The cells' bounding boxes (cells, d).
        star: Cell -> vertices, vertex -> cells offsets and cells, and the number of cells
            searched (:meth:`fempm.particles.location.CellLocator.vertex_star`).
        num_owned: Cells below it are this rank's own, the others ghosts.
        x0, K: The affine map of each cell (:attr:`fempm.meshes.geometry.CellGeometry.kernel_geometry`).
        out: (cells (n, Q) int32, reference coordinates (n Q, d), weights (n, Q)) to fill: the
            pieces of a box first, the other samples of no weight.
        guessed: Whether ``out`` holds samples of the particles already (the last step's):
            the cells of a particle's pieces there are searched first, and when the box's pieces
            in them cover it, no other cell is (a guess only: the rows of other particles, or
            none, cost a search).

    Returns:
        The most pieces of one box (more than ``Q``: call again with a larger ``Q``), the number
        of boxes not wholly covered with a piece in a ghost cell (part of them may lie in
        cells this rank does not have), and the number of boxes left without samples (that met
        more than :data:`MAX_VISITED` cells, or none).
    """
    d, simplex = cell_type
    sc, Y, w = out
    needed, reaching, failed = _kernel(d, simplex)(x, np.ascontiguousarray(ell), cells, verts, blo, bhi, *star,
                                                    num_owned, x0, K, bool(guessed), sc, Y, w)
    return int(needed), int(reaching), int(failed)
