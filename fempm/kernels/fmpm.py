r"""FMPM(k) for point particles on affine degree-1 cells, compiled
(:class:`fempm.stepping.fmpm_mass.FMPMNodalMass` drives it; the numpy
:func:`fempm.transfer.fmpm.fmpm_solve` is its reference).

:func:`mass_apply` (one particle pass, a G2P of ``y`` and a P2G of the particles' mass times it):

.. math::
    (M_C y)_i = \sum_p M_p N_{ip} \sum_j N_{jp}\, y_j,

with lumped dofs ``lump`` left out of ``y`` and, in one more column, :math:`M_C 1_l` (the
couplings to the lumped dofs that :func:`fempm.transfer.fmpm.fmpm_solve` moves to the
diagonal); ghost entries are partial sums.

:func:`richardson` (one pass over the dofs): :math:`x \leftarrow x + m^{-1} (b - M_C' x)` on
the free components of the coupled dofs, :math:`M_C' x = M_C (x \odot 1_{\bar l}) + (M_C 1_l)
\odot x`; :func:`lumped_solve`: :math:`x = m^{-1} b` on the free components.
"""

from __future__ import annotations

import functools

import numpy as np

from fempm.kernels.shape import AVAILABLE, CELLS, is_affine, space_of

__all__ = ["lumped_solve", "mass_apply", "richardson"]

if AVAILABLE:
    from numba import njit

    from fempm.kernels.shape import shape

    @njit(cache=True, error_model="numpy")
    def lumped_solve(b, cb, mass, free, active_min, x):  # pragma: no cover - compiled
        """``x`` = ``b[:, cb:cb+k]`` / ``mass[:, 0]`` on the free components of dofs with mass
        above ``active_min``, else 0."""
        for i in range(len(x)):
            m = mass[i, 0]
            for j in range(x.shape[1]):
                x[i, j] = b[i, cb + j] / m if (m > active_min and free[i, j]) else 0.0

    @njit(cache=True, error_model="numpy")
    def richardson(x, b, cb, Mx, mass, free, active_min, lump, out):  # pragma: no cover - compiled
        """``out`` = one Richardson step from ``x`` for ``b[:, cb:cb+k]`` (``Mx``:
        :func:`mass_apply` of ``x``, its last column :math:`M_C 1_l` where ``lump`` has an entry
        per dof; the masses ``mass[:, 0]``)."""
        k = x.shape[1]
        lumping = lump.shape[0] > 0
        for i in range(len(x)):
            m = mass[i, 0]
            coupled = not (lumping and lump[i])
            for j in range(k):
                r = x[i, j]
                if m > active_min and free[i, j] and coupled:
                    mx = Mx[i, j] + (Mx[i, k] * x[i, j] if lumping else 0.0)
                    r += (b[i, cb + j] - mx) / m
                out[i, j] = r


@functools.cache
def mass_apply(cell: str):
    """``kernel(cells, X, K, cell_dofs, mass, y, lump, out)``: ``out[:, :k]`` += :math:`M_C y`
    for ``y`` (dofs, k) without its lumped dofs, and, where ``lump`` has an entry per dof,
    ``out[:, k]`` += :math:`M_C 1_l`; compiled for one cell type."""
    D, NK, SIMPLEX = CELLS[cell]
    AFFINE = is_affine(cell)
    DEGREE, BERNSTEIN = space_of(cell)

    @njit(cache=True, error_model="numpy")
    def kernel(cells, X, K, cell_dofs, mass, y, lump, out):  # pragma: no cover - compiled
        N = np.empty(NK)
        G = np.empty((NK, D))
        k = y.shape[1]
        u = np.empty(k)
        lumping = lump.shape[0] > 0
        for p in range(len(cells)):
            c = cells[p]
            shape(X, p, K, c, SIMPLEX, AFFINE, D, NK, N, G, DEGREE, BERNSTEIN)
            for j in range(k):
                u[j] = 0.0
            ul = 0.0
            for a in range(NK):
                i = cell_dofs[c, a]
                if lumping and lump[i]:
                    ul += N[a]
                else:
                    for j in range(k):
                        u[j] += N[a] * y[i, j]
            m = mass[p]
            for a in range(NK):
                i = cell_dofs[c, a]
                w = m * N[a]
                for j in range(k):
                    out[i, j] += w * u[j]
                if lumping:
                    out[i, k] += w * ul

    return kernel
