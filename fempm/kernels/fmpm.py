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
\odot x`; :func:`lumped_solve`: :math:`x = m^{-1} b` on the free components. Both clear the
kept output of the next :func:`mass_apply` in their pass.
"""

from __future__ import annotations

import functools

import numpy as np

from fempm.kernels.choice import INLINE
from fempm.kernels.shape import AVAILABLE, CELLS, MULTILINEAR, is_affine, space_of

__all__ = ["add_column", "coupled", "generic_mass_apply", "lumped_solve", "mass_apply", "planar_mass_apply",
           "richardson"]

if AVAILABLE:
    from numba import njit

    from fempm.kernels.planar import add_pair, basis
    from fempm.kernels.shape import shape, shape_values

    @njit(inline=INLINE)
    def coupled(lump, i0, i1, i2, i3, e0, e1, e2, e3, quad):  # pragma: no cover - compiled
        """The values ``e`` of a cell's dofs with those of the lumped dofs (``lump``) set to 0
        (the fourth on a quadrilateral only)."""
        return (0.0 if lump[i0] else e0, 0.0 if lump[i1] else e1, 0.0 if lump[i2] else e2,
                0.0 if (quad and lump[i3]) else e3)

    @njit(inline=INLINE)
    def add_column(out, col, i0, i1, i2, i3, N0, N1, N2, N3, t, quad):  # pragma: no cover - compiled
        """``out[i_a, col] += N_a t`` over the cell's dofs (the fourth on a quadrilateral only)."""
        out[i0, col] += N0 * t
        out[i1, col] += N1 * t
        out[i2, col] += N2 * t
        if quad:
            out[i3, col] += N3 * t

    @njit(cache=True, error_model="numpy")
    def lumped_solve(b, cb, mass, free, active_min, x, zero):  # pragma: no cover - compiled
        """``x`` = ``b[:, cb:cb+k]`` / ``mass[:, 0]`` on the free components of dofs with mass
        above ``active_min`` (``x`` zero elsewhere: its other rows are not written); the rows
        of ``zero`` (a kept :func:`mass_apply` output, or none) with mass set to 0 in the same
        pass (the rows :func:`mass_apply` adds to)."""
        zeroing = zero.shape[0] > 0
        for i in range(len(x)):
            m = mass[i, 0]
            if not m > 0.0:
                continue
            if zeroing:
                for j in range(zero.shape[1]):
                    zero[i, j] = 0.0
            if m > active_min:
                for j in range(x.shape[1]):
                    x[i, j] = b[i, cb + j] / m if free[i, j] else 0.0

    @njit(cache=True, error_model="numpy")
    def richardson(x, b, cb, Mx, mass, free, active_min, lump, out, rest, zero):  # pragma: no cover - compiled
        """One Richardson step from ``x`` for ``b[:, cb:cb+k]`` (``Mx``: :func:`mass_apply` of
        ``x``, its last column :math:`M_C 1_l` where ``lump`` has an entry per dof; the masses
        ``mass[:, 0]``) into ``out`` and, past its columns, ``rest`` (e.g. a velocity and an
        acceleration solved side by side, each contiguous), on the dofs with mass above
        ``active_min`` (``x``, ``out`` and ``rest`` zero on the others: not read or written);
        with ``zero`` the rows of ``Mx`` with mass are set to 0 once read (for the next
        :func:`mass_apply`)."""
        k = x.shape[1]
        k1 = out.shape[1]
        lumping = lump.shape[0] > 0
        for i in range(len(x)):
            m = mass[i, 0]
            if not m > 0.0:
                continue
            if m > active_min:
                coupled_row = not (lumping and lump[i])
                for j in range(k):
                    r = x[i, j]
                    if free[i, j] and coupled_row:
                        mx = Mx[i, j] + (Mx[i, k] * x[i, j] if lumping else 0.0)
                        r += (b[i, cb + j] - mx) / m
                    if j < k1:
                        out[i, j] = r
                    else:
                        rest[i, j - k1] = r
            if zero:
                for j in range(Mx.shape[1]):
                    Mx[i, j] = 0.0


@functools.cache
def mass_apply(cell: str):
    """``kernel(cells, X, K, cell_dofs, mass, y, lump, out)``: ``out[:, :k]`` += :math:`M_C y`
    for ``y`` (dofs, k) without its lumped dofs, and, where ``lump`` has an entry per dof,
    ``out[:, k]`` += :math:`M_C 1_l`; compiled for one cell type (on triangles and
    quadrilaterals of degree 1 in scalar code, two columns at a time: :func:`planar_mass_apply`)."""
    if cell in ("triangle", "quadrilateral", "quadrilateral" + MULTILINEAR):
        planar = planar_mass_apply(cell == "triangle")
        generic = generic_mass_apply(cell)
        return lambda cells, X, K, cell_dofs, mass, y, lump, out: (
            planar if y.shape[1] % 2 == 0 else generic)(cells, X, K, cell_dofs, mass, y, lump, out)
    return generic_mass_apply(cell)


@functools.cache
def planar_mass_apply(simplex: bool):
    """:func:`mass_apply` on triangles (``simplex``) or quadrilaterals (affine or not: the
    values alone) for an even number of columns, in local scalars."""
    QUAD = not simplex

    @njit(cache=True, error_model="numpy")
    def kernel(cells, X, K, cell_dofs, mass, y, lump, out):  # pragma: no cover - compiled
        k = y.shape[1]
        lumping = lump.shape[0] > 0
        for p in range(len(cells)):
            c = cells[p]
            N0, N1, N2, N3 = basis(X[p, 0], X[p, 1], 0.0, 0.0, 0.0, 0.0, simplex)[:4]
            i0, i1, i2 = cell_dofs[c, 0], cell_dofs[c, 1], cell_dofs[c, 2]
            i3 = cell_dofs[c, 3] if QUAD else i0
            e0, e1, e2, e3 = N0, N1, N2, N3  # the coupled dofs' values
            if lumping:
                e0, e1, e2, e3 = coupled(lump, i0, i1, i2, i3, N0, N1, N2, N3, QUAD)
            m = mass[p]
            for j in range(0, k, 2):
                u0 = e0 * y[i0, j] + e1 * y[i1, j] + e2 * y[i2, j]
                u1 = e0 * y[i0, j + 1] + e1 * y[i1, j + 1] + e2 * y[i2, j + 1]
                if QUAD:
                    u0 += e3 * y[i3, j]
                    u1 += e3 * y[i3, j + 1]
                add_pair(out, j, (i0, i1, i2, i3), (N0, N1, N2, N3), m * u0, m * u1, QUAD)
            if lumping:
                ul = m * ((N0 - e0) + (N1 - e1) + (N2 - e2) + ((N3 - e3) if QUAD else 0.0))
                add_column(out, k, i0, i1, i2, i3, N0, N1, N2, N3, ul, QUAD)

    return kernel


@functools.cache
def generic_mass_apply(cell: str):
    """:func:`mass_apply` of any kernel cell type (the reference of :func:`planar_mass_apply`)."""
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
            if DEGREE == 1:  # the values alone: no Jacobian
                shape_values(X, p, SIMPLEX, D, NK, N)
            else:
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
