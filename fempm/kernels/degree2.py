r"""The degree-2 Lagrange and Bernstein bases on a simplex from its barycentric coordinates,
for the compiled passes (:func:`fempm.kernels.shape.shape` calls :func:`degree2`, compiled
once rather than inlined into every kernel); basix's numbering of the edges and the
equispaced/GLL nodes (equal at degree 2) are the reference.
"""

from __future__ import annotations

from fempm.kernels.choice import INLINE

__all__: list[str] = []

try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency
    njit = None

if njit is not None:
    @njit(inline=INLINE)
    def edge_vertices(q, t):  # pragma: no cover - compiled
        """The vertices (a, b), a < b, of edge ``q`` of the reference simplex of dimension ``t``
        in basix's numbering (triangle: (1, 2), (0, 2), (0, 1); tetrahedron: (2, 3), (1, 3),
        (1, 2), (0, 3), (0, 2), (0, 1); interval: (0, 1))."""
        if t == 1:
            return 0, 1
        if t == 2:
            return (1 if q == 0 else 0), (2 if q < 2 else 1)
        if q < 3:
            return (2 if q == 0 else 1), (3 if q < 2 else 2)
        return 0, 6 - q

    @njit(cache=True)  # not inlined: compiled once, not into every kernel
    def degree2(t, k, bernstein, N, G, gradients):  # pragma: no cover - compiled
        r"""The degree-2 basis on a simplex from the barycentric coordinates :math:`\lambda_a` in
        ``N[:t+1]`` (and their gradients in ``G[:t+1]``), in place: Lagrange
        :math:`\lambda_a (2\lambda_a - 1)` at the vertices and :math:`4 \lambda_a \lambda_b` on
        edge (a, b) (:func:`edge_vertices`); Bernstein :math:`\lambda_a^2` and
        :math:`2 \lambda_a \lambda_b`."""
        w = 2.0 if bernstein else 4.0
        for q in range(k - t - 1):
            a, b = edge_vertices(q, t)
            la, lb = N[a], N[b]
            N[t + 1 + q] = w * la * lb
            if gradients:
                for e in range(t):
                    G[t + 1 + q, e] = w * (lb * G[a, e] + la * G[b, e])
        for a in range(t + 1):
            la = N[a]
            N[a] = la * la if bernstein else la * (2.0 * la - 1.0)
            if gradients:
                f = 2.0 * la if bernstein else 4.0 * la - 1.0
                for e in range(t):
                    G[a, e] *= f
