r"""The piece of a particle's box in one cell, compiled: its volume and the reference coordinates
of its centroid (:func:`fempm.kernels.boxes.box_samples` sums them into exact GIMP samples).

* :func:`triangle_piece`: the box's image in the reference triangle (a parallelogram) clipped
  by the triangle's edges that cross it (Sutherland and Hodgman), its area and centroid by the
  shoelace formula, the area times :math:`|\det J|`;
* :func:`tetrahedron_piece`: by the divergence theorem over the piece's faces,
  :math:`|P| = \tfrac13 \oint_{\partial P} x \cdot n`,
  :math:`\int_P x = \tfrac14 \oint_{\partial P} x\, (x \cdot n)`, the faces being the
  tetrahedron's faces clipped by the box and the box's faces clipped by the tetrahedron.

:class:`fempm.transfer.box_average.BoxIntegrator` is the reference
(``tests/kernels/test_boxes.py``).
"""

from __future__ import annotations

from fempm.kernels.choice import INLINE
from fempm.kernels.shape import AVAILABLE

__all__ = ["tetrahedron_piece", "triangle_piece"]

if AVAILABLE:
    from numba import njit

    @njit(inline=INLINE)
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

    @njit(inline=INLINE)
    def triangle_piece(x, p, ell, x0, K, c, P, cen):  # pragma: no cover - compiled
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

    @njit(inline=INLINE)
    def _clip3(P, src, n, f0, f1, f2, f3, strict, dst):  # pragma: no cover - compiled
        """:func:`_clip_polygon` in 3D: the part where ``f0 + f1 x + f2 y + f3 z`` is >= 0 (> 0
        with ``strict``)."""
        m = 0
        j = src + n - 1
        fj = f0 + f1 * P[j, 0] + f2 * P[j, 1] + f3 * P[j, 2]
        for i in range(src, src + n):
            fi = f0 + f1 * P[i, 0] + f2 * P[i, 1] + f3 * P[i, 2]
            inside_i = fi > 0.0 if strict else fi >= 0.0
            inside_j = fj > 0.0 if strict else fj >= 0.0
            if inside_i != inside_j:
                t = fj / (fj - fi)
                for e in range(3):
                    P[dst + m, e] = P[j, e] + t * (P[i, e] - P[j, e])
                m += 1
            if inside_i:
                for e in range(3):
                    P[dst + m, e] = P[i, e]
                m += 1
            j, fj = i, fi
        return m

    @njit(inline=INLINE)
    def _fan(P, at, n, acc):  # pragma: no cover - compiled
        r"""Add the cones from the origin over the fan of the polygon in rows ``at`` to
        ``at + n`` of ``P``: 6 times their volumes to ``acc[0]``, 24 times their first moments to
        ``acc[1:]``."""
        for i in range(at + 1, at + n - 1):
            a0, a1, a2 = P[at, 0], P[at, 1], P[at, 2]
            b0, b1, b2 = P[i, 0], P[i, 1], P[i, 2]
            c0, c1, c2 = P[i + 1, 0], P[i + 1, 1], P[i + 1, 2]
            det = a0 * (b1 * c2 - b2 * c1) - a1 * (b0 * c2 - b2 * c0) + a2 * (b0 * c1 - b1 * c0)
            acc[0] += det
            acc[1] += det * (a0 + b0 + c0)
            acc[2] += det * (a1 + b1 + c1)
            acc[3] += det * (a2 + b2 + c2)

    @njit(inline=INLINE)
    def tetrahedron_piece(T, x0, K, c, lo, hi, P, acc, cen):  # pragma: no cover - compiled
        r"""The volume of the part of the box ``[lo, hi]`` in tetrahedron ``c`` (vertices ``T``)
        and its centroid's reference coordinates ``cen``, by the divergence theorem over the
        piece's faces, :math:`|P| = \frac13 \oint x \cdot n`, :math:`\int_P x =
        \frac14 \oint x\, (x \cdot n)`: the tetrahedron's faces clipped by the box, and the
        box's faces clipped by the tetrahedron (strictly: a box face on a face of the
        tetrahedron counts once), about the box's centre (``P`` (32, 3), ``acc`` (4,): work)."""
        o0, o1, o2 = 0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])
        for e in range(3):  # apart: no volume in common
            tlo = min(min(T[0, e], T[1, e]), min(T[2, e], T[3, e]))
            thi = max(max(T[0, e], T[1, e]), max(T[2, e], T[3, e]))
            if not (tlo < hi[e] and thi > lo[e]):
                return 0.0
        for e in range(4):
            acc[e] = 0.0
        for k in range(4):  # the face opposite vertex k, turned outwards
            i, j, m = (k + 1) % 4, (k + 2) % 4, (k + 3) % 4
            u0, u1, u2 = T[j, 0] - T[i, 0], T[j, 1] - T[i, 1], T[j, 2] - T[i, 2]
            w0, w1, w2 = T[m, 0] - T[i, 0], T[m, 1] - T[i, 1], T[m, 2] - T[i, 2]
            n0, n1, n2 = u1 * w2 - u2 * w1, u2 * w0 - u0 * w2, u0 * w1 - u1 * w0
            if n0 * (T[k, 0] - T[i, 0]) + n1 * (T[k, 1] - T[i, 1]) + n2 * (T[k, 2] - T[i, 2]) > 0.0:
                j, m = m, j
            for r, v in enumerate((i, j, m)):
                P[r, 0], P[r, 1], P[r, 2] = T[v, 0] - o0, T[v, 1] - o1, T[v, 2] - o2
            n, at = 3, 0
            for a in range(3):
                oa = o0 if a == 0 else (o1 if a == 1 else o2)
                for side in (-1.0, 1.0):
                    if n == 0:
                        break
                    f0 = oa - lo[a] if side < 0.0 else hi[a] - oa
                    f1, f2, f3 = -side if a == 0 else 0.0, -side if a == 1 else 0.0, -side if a == 2 else 0.0
                    n = _clip3(P, at, n, f0, f1, f2, f3, False, 16 - at)
                    at = 16 - at
            if n >= 3:
                _fan(P, at, n, acc)
        # the barycentric coordinates about the box centre: lambda_i = g_i + sum_e K[c, i-1, e] x_e
        g1 = K[c, 0, 0] * (o0 - x0[c, 0]) + K[c, 0, 1] * (o1 - x0[c, 1]) + K[c, 0, 2] * (o2 - x0[c, 2])
        g2 = K[c, 1, 0] * (o0 - x0[c, 0]) + K[c, 1, 1] * (o1 - x0[c, 1]) + K[c, 1, 2] * (o2 - x0[c, 2])
        g3 = K[c, 2, 0] * (o0 - x0[c, 0]) + K[c, 2, 1] * (o1 - x0[c, 1]) + K[c, 2, 2] * (o2 - x0[c, 2])
        for a in range(3):  # the box's faces, corners counter-clockwise about the outward normal
            b, q = (a + 1) % 3, (a + 2) % 3
            for side in (-1.0, 1.0):
                h = 0.5 * (hi[a] - lo[a]) * side
                hb, hq = 0.5 * (hi[b] - lo[b]), 0.5 * (hi[q] - lo[q])
                for r in range(4):
                    sb = -1.0 if r == 0 or r == 3 else 1.0
                    sq = -1.0 if r < 2 else 1.0
                    if side < 0.0:
                        sq = -sq  # the other way round
                    P[r, a], P[r, b], P[r, q] = h, sb * hb, sq * hq
                n, at = 4, 0
                for i in range(4):
                    if n == 0:
                        break
                    if i == 0:
                        f0 = 1.0 - g1 - g2 - g3
                        f1 = -(K[c, 0, 0] + K[c, 1, 0] + K[c, 2, 0])
                        f2 = -(K[c, 0, 1] + K[c, 1, 1] + K[c, 2, 1])
                        f3 = -(K[c, 0, 2] + K[c, 1, 2] + K[c, 2, 2])
                    else:
                        f0 = g1 if i == 1 else (g2 if i == 2 else g3)
                        f1, f2, f3 = K[c, i - 1, 0], K[c, i - 1, 1], K[c, i - 1, 2]
                    n = _clip3(P, at, n, f0, f1, f2, f3, True, 16 - at)
                    at = 16 - at
                if n >= 3:
                    _fan(P, at, n, acc)
        volume = acc[0] / 6.0
        if not volume > 0.0:
            return 0.0
        m0, m1, m2 = acc[1] / (24.0 * volume) + o0, acc[2] / (24.0 * volume) + o1, acc[3] / (24.0 * volume) + o2
        for i in range(3):
            cen[i] = K[c, i, 0] * (m0 - x0[c, 0]) + K[c, i, 1] * (m1 - x0[c, 1]) + K[c, i, 2] * (m2 - x0[c, 2])
        return volume
