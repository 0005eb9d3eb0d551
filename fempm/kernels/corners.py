r"""The geometry of particle domains given by their corners, compiled
(:func:`fempm.particles.corners.domain_geometry` calls it; its numpy formulas are the reference):
the corner weights :math:`w_c = |\Omega_p|^{-1} \int_{\Omega_p} \phi_c`, gradient weights
:math:`g_c = |\Omega_p|^{-1} \int_{\Omega_p} \nabla \phi_c`, volumes and centroids
:math:`\sum_c w_c y_c` of simplices (:math:`w_c = 1/(d+1)`, :math:`g_c = \nabla \lambda_c`) and of
quadrilaterals / hexahedra (the 2-point Gauss rule of the multilinear map), in one pass, with
the number of degenerate or twisted domains (a Jacobian determinant zero or changing sign);
and :func:`corner_geometry`, one 2D domain's in closed form, for CPDI2's moving pass
(:mod:`fempm.kernels.planar_samples`)."""

from __future__ import annotations

import numpy as np

from fempm.kernels.choice import INLINE
from fempm.kernels.shape import AVAILABLE

__all__ = ["AVAILABLE", "corner_geometry", "inverse", "planar_geometry", "simplex_geometry", "tensor_geometry"]

if AVAILABLE:
    from numba import njit

    @njit(inline=INLINE)
    def inverse(A, d, B):  # pragma: no cover - compiled
        """B <- A^-1 for d <= 3 in closed form (inf/NaN where A is singular); returns det A."""
        if d == 1:
            det = A[0, 0]
            B[0, 0] = 1.0 / det
        elif d == 2:
            det = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
            B[0, 0], B[0, 1] = A[1, 1] / det, -A[0, 1] / det
            B[1, 0], B[1, 1] = -A[1, 0] / det, A[0, 0] / det
        else:
            c00 = A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1]
            c01 = A[1, 2] * A[2, 0] - A[1, 0] * A[2, 2]
            c02 = A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]
            det = A[0, 0] * c00 + A[0, 1] * c01 + A[0, 2] * c02
            B[0, 0] = c00 / det
            B[1, 0] = c01 / det
            B[2, 0] = c02 / det
            B[0, 1] = (A[0, 2] * A[2, 1] - A[0, 1] * A[2, 2]) / det
            B[1, 1] = (A[0, 0] * A[2, 2] - A[0, 2] * A[2, 0]) / det
            B[2, 1] = (A[0, 1] * A[2, 0] - A[0, 0] * A[2, 1]) / det
            B[0, 2] = (A[0, 1] * A[1, 2] - A[0, 2] * A[1, 1]) / det
            B[1, 2] = (A[0, 2] * A[1, 0] - A[0, 0] * A[1, 2]) / det
            B[2, 2] = (A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]) / det
        return det

    @njit(inline=INLINE)
    def _centroid(corners, w, p, centroid):  # pragma: no cover - compiled
        r"""``centroid[p]`` <- :math:`\sum_c w_c y_c` of domain ``p``."""
        for i in range(corners.shape[2]):
            s = 0.0
            for c in range(corners.shape[1]):
                s += w[p, c] * corners[p, c, i]
            centroid[p, i] = s

    @njit(cache=True, error_model="numpy")
    def simplex_geometry(corners, w, g, vol, centroid):  # pragma: no cover - compiled
        """Simplices (n, d + 1, d); returns the number of degenerate ones."""
        n, k, d = corners.shape
        J, K = np.empty((d, d)), np.empty((d, d))
        factorial = 1.0
        for i in range(2, d + 1):
            factorial *= i
        bad = 0
        for p in range(n):
            for i in range(d):
                for c in range(1, k):
                    J[i, c - 1] = corners[p, c, i] - corners[p, 0, i]
            det = inverse(J, d, K)
            if not (det > 0.0 or det < 0.0):
                bad += 1
            for i in range(d):
                s = 0.0
                for r in range(d):
                    s += K[r, i]
                    g[p, r + 1, i] = K[r, i]
                g[p, 0, i] = -s
            for c in range(k):
                w[p, c] = 1.0 / k
            vol[p] = abs(det) / factorial
            _centroid(corners, w, p, centroid)
        return bad

    @njit(cache=True, error_model="numpy")
    def tensor_geometry(corners, phi, dphi, weights, w, g, vol, centroid):  # pragma: no cover - compiled
        """Quadrilaterals / hexahedra (n, 2^d, d) with the rule's corner values ``phi`` (G, k),
        reference gradients ``dphi`` (G, k, d) and ``weights`` (G,); returns the number of
        degenerate or twisted ones."""
        n, k, d = corners.shape
        G = phi.shape[0]
        J, Ji = np.empty((d, d)), np.empty((d, d))
        bad = 0
        for p in range(n):
            for c in range(k):
                w[p, c] = 0.0
                for i in range(d):
                    g[p, c, i] = 0.0
            V = 0.0
            pos, neg = 0, 0
            for q in range(G):
                for i in range(d):
                    for b in range(d):
                        s = 0.0
                        for c in range(k):
                            s += corners[p, c, i] * dphi[q, c, b]
                        J[i, b] = s
                det = inverse(J, d, Ji)
                if det > 0.0:
                    pos += 1
                elif det < 0.0:
                    neg += 1
                dV = abs(det) * weights[q]
                V += dV
                for c in range(k):
                    w[p, c] += dV * phi[q, c]
                    for i in range(d):
                        s = 0.0
                        for b in range(d):
                            s += Ji[b, i] * dphi[q, c, b]
                        g[p, c, i] += dV * s
            if not (pos == G or neg == G):
                bad += 1
            vol[p] = V
            for c in range(k):
                w[p, c] /= V
                for i in range(d):
                    g[p, c, i] /= V
            _centroid(corners, w, p, centroid)
        return bad

    @njit(inline=INLINE)
    def corner_geometry(yc, p, w, gw):  # pragma: no cover - compiled
        r"""CPDI2: the weights ``w[p]``, ``gw[p]`` of domain ``p`` of corners ``yc[p]`` (a triangle,
        or a quadrilateral in :func:`fempm.particles.corners.corner_signs` order) in closed form;
        returns (volume, centroid, twisted). With the map
        :math:`x = a + b\xi + c\eta + e\xi\eta` of the quadrilateral,
        :math:`\det J = A_0 + A_1 \xi + A_2 \eta` (:math:`A_0 = b \times c`,
        :math:`A_1 = b \times e`, :math:`A_2 = e \times c`), so :math:`|\Omega| = 4 |A_0|`,
        :math:`w_c = (A_0 + (A_1 s_{c0} + A_2 s_{c1}) / 3) / (4 A_0)`; and by the divergence
        theorem :math:`g_c = |\Omega|^{-1} \oint \phi_c n = (y_{c^+} - y_{c^-})^\perp / (2
        \Omega_\pm)` with :math:`c^\pm` the corners after and before :math:`c` around the
        domain, :math:`(u, v)^\perp = (v, -u)` and :math:`\Omega_\pm` the signed area (a
        triangle: :math:`w_c = 1/3`, :math:`g_c = \nabla \lambda_c`). A twisted domain: the
        Jacobian zero or of two signs at the 2-point Gauss rule's points (as
        :func:`fempm.kernels.corners.tensor_geometry`)."""
        x0, y0, x1, y1, x2, y2 = yc[p, 0, 0], yc[p, 0, 1], yc[p, 1, 0], yc[p, 1, 1], yc[p, 2, 0], yc[p, 2, 1]
        if yc.shape[1] == 3:
            a2 = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0)  # twice the signed area; corners 0 -> 1 -> 2
            for c in range(3):
                w[p, c] = 1.0 / 3.0
            gw[p, 0, 0], gw[p, 0, 1] = (y1 - y2) / a2, (x2 - x1) / a2
            gw[p, 1, 0], gw[p, 1, 1] = (y2 - y0) / a2, (x0 - x2) / a2
            gw[p, 2, 0], gw[p, 2, 1] = (y0 - y1) / a2, (x1 - x0) / a2
            return 0.5 * abs(a2), (x0 + x1 + x2) / 3.0, (y0 + y1 + y2) / 3.0, not (a2 > 0.0 or a2 < 0.0)
        x3, y3 = yc[p, 3, 0], yc[p, 3, 1]
        bx, by = 0.25 * (-x0 - x1 + x2 + x3), 0.25 * (-y0 - y1 + y2 + y3)
        cx, cy = 0.25 * (-x0 + x1 - x2 + x3), 0.25 * (-y0 + y1 - y2 + y3)
        ex, ey = 0.25 * (x0 - x1 - x2 + x3), 0.25 * (y0 - y1 - y2 + y3)
        A0, A1, A2 = bx * cy - by * cx, bx * ey - by * ex, ex * cy - ey * cx
        r = 1.0 / np.sqrt(3.0)
        pos, neg = 0, 0
        for t in (A0 + r * (A1 + A2), A0 + r * (A1 - A2), A0 - r * (A1 - A2), A0 - r * (A1 + A2)):
            if t > 0.0:
                pos += 1
            elif t < 0.0:
                neg += 1
        a4 = 4.0 * A0  # the signed area; around the domain 0 -> 2 -> 3 -> 1
        w0, w1 = (A0 - (A1 + A2) / 3.0) / a4, (A0 + (A2 - A1) / 3.0) / a4
        w2, w3 = (A0 + (A1 - A2) / 3.0) / a4, (A0 + (A1 + A2) / 3.0) / a4
        w[p, 0], w[p, 1], w[p, 2], w[p, 3] = w0, w1, w2, w3
        h = 0.5 / a4
        gw[p, 0, 0], gw[p, 0, 1] = h * (y2 - y1), h * (x1 - x2)
        gw[p, 2, 0], gw[p, 2, 1] = h * (y3 - y0), h * (x0 - x3)
        gw[p, 3, 0], gw[p, 3, 1] = h * (y1 - y2), h * (x2 - x1)
        gw[p, 1, 0], gw[p, 1, 1] = h * (y0 - y3), h * (x3 - x0)
        return (abs(a4), w0 * x0 + w1 * x1 + w2 * x2 + w3 * x3, w0 * y0 + w1 * y1 + w2 * y2 + w3 * y3,
                not (pos == 4 or neg == 4))

    @njit(cache=True, error_model="numpy")
    def planar_geometry(corners, w, g, vol, centroid):  # pragma: no cover - compiled
        """Triangles or quadrilaterals (n, 3 or 4, 2) by :func:`corner_geometry` (the weights
        CPDI2's moving pass gives the corners it moves, bit for bit); returns the number of
        degenerate or twisted ones."""
        bad = 0
        for p in range(len(corners)):
            vol[p], centroid[p, 0], centroid[p, 1], twisted = corner_geometry(corners, p, w, g)
            if twisted:
                bad += 1
        return bad
