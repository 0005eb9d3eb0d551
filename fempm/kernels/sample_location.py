"""Where the sample points of particle domains lie: :func:`locate_samples` (each sample's cell
and reference coordinates) and :func:`at_samples` (nodal values at the samples), the location
side of :mod:`fempm.kernels.samples`."""

from __future__ import annotations

import functools

import numpy as np

from fempm.kernels.bundles import Star
from fempm.kernels.shape import AVAILABLE, CELLS, is_affine

__all__ = ["at_samples", "locate_samples"]

if AVAILABLE:
    from numba import njit

    from fempm.kernels.shape import inside_after_pull_back, shape_values, star_search


@functools.cache
def _locate_kernel(cell: str):
    T, _, SIMPLEX = CELLS[cell]
    AFFINE = is_affine(cell)

    @njit(cache=True)
    def locate(y, cells, Q, x0, K, star, tol, guess, sc, Y):  # pragma: no cover
        missing = 0
        guessed = guess.shape[0] == len(cells)
        for p in range(len(cells)):
            c = cells[p]
            for q in range(Q):
                r = p * Q + q
                e = guess[p, q] if guessed else -1
                if e >= 0 and e != c and inside_after_pull_back(y, r, x0, K, e, SIMPLEX, T, tol, Y, AFFINE):
                    sc[p, q] = e
                elif inside_after_pull_back(y, r, x0, K, c, SIMPLEX, T, tol, Y, AFFINE):
                    sc[p, q] = c
                else:
                    e = star_search(y, r, x0, K, c, star, SIMPLEX, T, tol, Y, AFFINE)
                    sc[p, q] = e
                    if e < 0:
                        missing += 1
        return missing

    return locate


def locate_samples(y, cells, Q: int, x0, K, star: Star, cell: str, tol: float, guess=None, out=None):
    """Cells (n, Q) and reference coordinates (n Q, t) of samples ``y`` (n Q, d) of particles in
    ``cells`` of the kernel cell type ``cell`` (geometry ``x0``, ``K``:
    :attr:`fempm.meshes.geometry.CellGeometry.kernel_geometry`): the sample's cell in ``guess``
    (n, Q; e.g. the last step's), else the particle's cell or the first of its vertex star
    (``star``: cell -> vertices, vertex -> cells offsets and cells, the cells searched) that
    holds it, -1 where none does; and the number of such samples. ``out``: the arrays (cells,
    coordinates) to fill (the cells may be ``guess``; on multilinear cells the coordinates are
    Newton's first guess)."""
    n = len(cells)
    t = CELLS[cell][0]
    sc, Y = out if out is not None else (np.empty((n, Q), dtype=np.int32), np.zeros((n * Q, t)))
    guess = np.zeros((0, Q), dtype=np.int32) if guess is None else guess
    missing = _locate_kernel(cell)(y, cells, Q, x0, K, star, float(tol), guess, sc, Y)
    return sc, Y, int(missing)


@functools.cache
def _at_samples_kernel(cell: str):
    D, NK, SIMPLEX = CELLS[cell]

    @njit(cache=True, error_model="numpy")
    def kernel(sc, Y, K, cell_dofs, u, out):  # pragma: no cover - compiled
        N = np.empty(NK)
        Q = sc.shape[1]
        for p in range(sc.shape[0]):
            for q in range(Q):
                r = p * Q + q
                c = sc[p, q]
                shape_values(Y, r, SIMPLEX, D, NK, N)
                for j in range(u.shape[1]):
                    s = 0.0
                    for a in range(NK):
                        s += N[a] * u[cell_dofs[c, a], j]
                    out[p, q, j] = s

    return kernel


def at_samples(cell: str, sc, Y, K, cell_dofs, u):
    r"""Nodal values ``u`` (dofs, k) at the samples, :math:`u(y_{pq}) = \sum_a N_a(y_{pq})
    u_{d(pq, a)}`, shape (n, Q, k) (e.g. the grid velocity at CPDI2 corners)."""
    out = np.empty((sc.shape[0], sc.shape[1], u.shape[1]))
    _at_samples_kernel(cell)(sc, Y, K, cell_dofs, np.ascontiguousarray(u), out)
    return out
