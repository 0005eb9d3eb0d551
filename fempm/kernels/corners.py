r"""The geometry of particle domains given by their corners, compiled
(:func:`fempm.particles.corners.domain_geometry` calls it; its numpy formulas are the reference):
the corner weights :math:`w_c = |\Omega_p|^{-1} \int_{\Omega_p} \phi_c`, gradient weights
:math:`g_c = |\Omega_p|^{-1} \int_{\Omega_p} \nabla \phi_c`, volumes and centroids
:math:`\sum_c w_c y_c` of simplices (:math:`w_c = 1/(d+1)`, :math:`g_c = \nabla \lambda_c`) and of
quadrilaterals / hexahedra (the 2-point Gauss rule of the multilinear map), in one pass, with
the number of degenerate or twisted domains (a Jacobian determinant zero or changing sign)."""

from __future__ import annotations

import numpy as np

from fempm.kernels.shape import AVAILABLE

__all__ = ["AVAILABLE", "inverse", "simplex_geometry", "tensor_geometry"]

if AVAILABLE:
    from numba import njit

    @njit(inline="always")
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

    @njit(inline="always")
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
