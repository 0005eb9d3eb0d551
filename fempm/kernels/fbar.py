r"""The compiled passes of F-bar on point particles (:class:`fempm.stepping.fbar_grid.FBarPointGrid`).

The nodal-patch average of :mod:`fempm.stepping.fbar` in passes over the particles, each
evaluating the basis on the fly (:func:`fempm.kernels.shape.shape`), with the nodal sums kept in a
(dofs, 2 B) array of B bodies, :math:`[\sum_q V_q N_{iq} \mid \sum_q V_q N_{iq} f_q]` per body,
turned into nodal averages once summed over ranks (:func:`fempm.kernels.patch.averages`):

* :func:`measure_kernel`: :math:`L_p = \sum_a v_a \otimes \nabla N_{ap}` and the measure the law
  averages, :math:`\Delta J_p = \det(I + \Delta t L_p)` or :math:`\Delta\theta_p = \Delta t\,
  \mathrm{tr}(L_p F_p)` (a law with ``volumetric_measure = "trace"``), added to the nodal sums;
* :func:`deform_kernel` (on the averages): the patch average
  :math:`\bar f_p = \sum_a N_{ap} (\sum V N f)_a / (\sum V N)_a`, the averaged deformation
  :math:`\bar F_p = (\overline{\Delta J}_p / \Delta J_p)^{1/d} (I + \Delta t L_p) F_p` or
  :math:`(I + \Delta t L_p) F_p + \frac1d(\overline{\Delta\theta}_p - \Delta\theta_p) I`, the
  volume, the checks of J and the compiled laws' stress (:func:`fempm.kernels.lumped.law_at`);
  :math:`\bar L_p` in the place of :math:`L_p` for the laws that keep their own ``stress`` (on
  triangles and quadrilaterals the G2P pass of :func:`fempm.kernels.planar.g2p_kernel` does it);
* :func:`pressure_kernel`: the pressures :math:`p_q = \mathrm{tr}\,\sigma_q / d` added to the nodal
  sums, which the P2G pass then takes (``Forces.patch``, :mod:`fempm.kernels.bundles`) to map the
  force of :math:`\sigma_p + (\bar p_p - p_p) I`, the stress whose divergence is the internal
  force of the averaged kinematics.

On tetrahedra and affine hexahedra the first two passes are those of :mod:`fempm.kernels.fbar_solid`
(the same equations in local scalars; the second where it keeps no :math:`\bar L_p`).
The numpy reference is :class:`fempm.stepping.fbar.FBar` (``rate``, ``force_stress``) on the
particle basis (``tests/kernels/test_fbar_kernels.py``).
"""

from __future__ import annotations

import functools

import numpy as np

from fempm.kernels import fbar_solid
from fempm.kernels.choice import INLINE
from fempm.kernels.shape import AVAILABLE, CELLS, is_affine, space_of

__all__ = ["deform_kernel", "measure_kernel", "pressure_kernel"]

if AVAILABLE:
    from numba import njit

    from fempm.kernels.affine import inverse
    from fempm.kernels.fbar_solid import root
    from fempm.kernels.kinematics import _det
    from fempm.kernels.kinematics import law_at
    from fempm.kernels.particle_checks import count_j
    from fempm.kernels.patch import add_corners, add_patch, nodal_ratio
    from fempm.kernels.planar import basis, increment_measure, inverse_jacobian
    from fempm.kernels.shape import shape, shape_values

    @njit(inline=INLINE)
    def values_at(X, p, K, c, D, NK, SIMPLEX, AFFINE, DEGREE, BERNSTEIN, N, G):  # pragma: no cover - compiled
        """The basis values ``N`` of particle ``p`` alone where they do not need the cell's map
        (degree 1: the reference coordinates), else with the gradients into ``G`` (the sizes and
        kinds as :func:`fempm.kernels.shape.shape`, compile-time constants)."""
        if DEGREE == 1:
            shape_values(X, p, SIMPLEX, D, NK, N)
        else:
            shape(X, p, K, c, SIMPLEX, AFFINE, D, NK, N, G, DEGREE, BERNSTEIN)

    @njit(inline=INLINE)
    def increment_det(L, p, dt, D):  # pragma: no cover - compiled
        r""":math:`\det(I + \Delta t L_p)` in closed form."""
        a = 1.0 + dt * L[p, 0, 0]
        if D == 1:
            return a
        b, c, e = dt * L[p, 0, 1], dt * L[p, 1, 0], 1.0 + dt * L[p, 1, 1]
        if D == 2:
            return a * e - b * c
        f, g, h, k = dt * L[p, 0, 2], dt * L[p, 1, 2], dt * L[p, 2, 0], dt * L[p, 2, 1]
        m = 1.0 + dt * L[p, 2, 2]
        return a * (e * m - g * k) - b * (c * m - g * h) + f * (c * k - e * h)


def _sizes(cell: str) -> tuple:
    """(D, NK, SIMPLEX, AFFINE, DEGREE, BERNSTEIN) of a kernels' cell type."""
    D, NK, SIMPLEX = CELLS[cell]
    return (D, NK, SIMPLEX, is_affine(cell), *space_of(cell))


@functools.cache
def measure_kernel(cell: str):
    r"""The first pass (see the module): ``measure(where, v_new, F, volume, body, by_trace, dt,
    L, value, out, dirty)`` writes :math:`L_p` into ``L`` (n, d, d) and the measure into ``value``
    (n,) (neither on :data:`fempm.kernels.lumped.PLANAR` cells, whose G2P pass computes both
    again: :func:`fempm.kernels.planar.increment_measure`), and adds the particles' volumes and
    measures to ``out`` (dofs, 2 B), marking the blocks it writes in ``dirty``
    (:mod:`fempm.kernels.patch`); ``by_trace`` (B,) says which bodies' laws average
    :math:`\mathrm{tr}\,F`."""
    D, NK, SIMPLEX, AFFINE, DEGREE, BERNSTEIN = _sizes(cell)
    PLANAR, QUAD = D == 2 and DEGREE == 1, not SIMPLEX
    SOLID = D == 3 and DEGREE == 1 and AFFINE  # tetrahedra, affine hexahedra: scalar code (fempm.kernels.solid)

    @njit(inline=INLINE)
    def measure2(p, c, arrays, by_trace, dt, out, dirty):  # pragma: no cover - compiled
        X, K, cell_dofs, v_new, F, volume, body = arrays
        X0, X1 = X[p, 0], X[p, 1]
        k00, k01, k10, k11 = inverse_jacobian(X0, X1, K, c, AFFINE)
        N0, N1, N2, N3, g0x, g0y, g1x, g1y, g2x, g2y, g3x, g3y = basis(X0, X1, k00, k01, k10, k11, SIMPLEX)
        i0, i1, i2 = cell_dofs[c, 0], cell_dofs[c, 1], cell_dofs[c, 2]
        i3 = cell_dofs[c, 3] if QUAD else i0
        a0, b0, a1, b1, a2, b2 = v_new[i0, 0], v_new[i0, 1], v_new[i1, 0], v_new[i1, 1], v_new[i2, 0], v_new[i2, 1]
        L00 = a0 * g0x + a1 * g1x + a2 * g2x
        L01 = a0 * g0y + a1 * g1y + a2 * g2y
        L10 = b0 * g0x + b1 * g1x + b2 * g2x
        L11 = b0 * g0y + b1 * g1y + b2 * g2y
        if QUAD:
            a3, b3 = v_new[i3, 0], v_new[i3, 1]
            L00, L01, L10, L11 = L00 + a3 * g3x, L01 + a3 * g3y, L10 + b3 * g3x, L11 + b3 * g3y
        b = body[p]
        f = increment_measure(F, p, dt, (L00, L01, L10, L11), by_trace[b])  # (the G2P pass computes it again)
        add_corners(out, dirty, ((i0, i1, i2, i3), (N0, N1, N2, N3)), b, volume[p], f, QUAD)

    if SOLID:
        return fbar_solid.measure_kernel(QUAD)

    @njit(cache=True, error_model="numpy")
    def measure(where, v_new, F, volume, body, by_trace, dt, L, value, out, dirty):  # pragma: no cover - compiled
        cells, X, K, cell_dofs = where
        bodies = out.shape[1] // 2
        N, G = np.empty(NK), np.empty((NK, D))
        for p in range(len(cells)):
            c = cells[p]
            if PLANAR:  # scalar code (as fempm.kernels.planar)
                measure2(p, c, (X, K, cell_dofs, v_new, F, volume, body), by_trace, dt, out, dirty)
                continue
            shape(X, p, K, c, SIMPLEX, AFFINE, D, NK, N, G, DEGREE, BERNSTEIN)
            for j in range(D):
                for e in range(D):
                    L[p, j, e] = 0.0
            for a in range(NK):
                i = cell_dofs[c, a]
                for j in range(D):
                    vij = v_new[i, j]
                    for e in range(D):
                        L[p, j, e] += vij * G[a, e]
            b = body[p]
            if by_trace[b]:
                t = 0.0
                for j in range(D):
                    for e in range(D):
                        t += L[p, j, e] * F[p, e, j]
                f = dt * t
            else:
                f = increment_det(L, p, dt, D)
            value[p] = f
            add_patch(out, dirty, (N, NK, cell_dofs, c), b, bodies, volume[p], f)

    return measure


@functools.cache
def deform_kernel(cell: str, keep_L: bool):
    r"""The second pass (see the module): ``deform(where, nodal, by_trace, dt, L, value, state,
    laws)`` sets ``F``, ``volume`` and the compiled laws' ``sigma`` of the ``state`` bundle
    (:mod:`fempm.kernels.bundles`) from the averaged deformation and, with ``keep_L``,
    :math:`\bar L_p` into ``L``; returns (#non-finite J, #J <= 0, min J, max J) as the G2P pass."""
    D, NK, SIMPLEX, AFFINE, DEGREE, BERNSTEIN = _sizes(cell)
    SOLID = D == 3 and DEGREE == 1 and AFFINE  # tetrahedra, affine hexahedra: scalar code

    if SOLID and not keep_L:
        return fbar_solid.deform_kernel(not SIMPLEX)

    @njit(cache=True, error_model="numpy")
    def deform(where, nodal, by_trace, dt, L, value, state, laws):  # pragma: no cover - compiled
        cells, X, K, cell_dofs = where
        F, volume0, volume, sigma, body = state.F, state.volume0, state.volume, state.sigma, state.body
        law, lam, mu = laws.law, laws.lam, laws.mu
        bodies = nodal.shape[1] // 2
        N, G = np.empty(NK), np.empty((NK, D))
        dF, Fn, Fi = np.empty((D, D)), np.empty((D, D)), np.empty((D, D))
        nonfinite_j, inverted, jmin, jmax = 0, 0, np.inf, -np.inf
        for p in range(len(cells)):
            c = cells[p]
            values_at(X, p, K, c, D, NK, SIMPLEX, AFFINE, DEGREE, BERNSTEIN, N, G)
            b = body[p]
            averaged = 0.0
            for a in range(NK):
                averaged += N[a] * nodal_ratio(nodal, cell_dofs[c, a], b, bodies)
            for j in range(D):
                for e in range(D):
                    dF[j, e] = dt * L[p, j, e] + (1.0 if j == e else 0.0)
            trace = by_trace[b]
            scale, shift = 1.0, 0.0
            if trace:
                shift = (averaged - value[p]) / D
            else:
                scale = root(averaged / value[p], D)
            for j in range(D):
                for e in range(D):
                    t = 0.0
                    for q in range(D):
                        t += dF[j, q] * F[p, q, e]
                    Fn[j, e] = scale * t + (shift if j == e else 0.0)
            if keep_L:  # (I + dt L-bar) F = F-bar
                if trace:
                    inverse(F[p], D, Fi)
                for j in range(D):
                    for e in range(D):
                        if trace:
                            L[p, j, e] += shift / dt * Fi[j, e]
                        else:
                            L[p, j, e] = (scale * dF[j, e] - (1.0 if j == e else 0.0)) / dt
            for j in range(D):
                for e in range(D):
                    F[p, j, e] = Fn[j, e]
            J = _det(F, p)
            volume[p] = J * volume0[p]
            ok, nonfinite_j, inverted, jmin, jmax = count_j(J, nonfinite_j, inverted, jmin, jmax)
            if ok:
                law_at(law[b], F, p, D, J, lam[b], mu[b], sigma)
        return nonfinite_j, inverted, jmin, jmax

    return deform


@functools.cache
def pressure_kernel(cell: str):
    r"""The third pass (see the module): ``pressures(where, volume, sigma, body, out, dirty)`` adds
    the particles' volumes and pressures :math:`\mathrm{tr}\,\sigma / d` to ``out`` (dofs, 2 B),
    marking the blocks it writes in ``dirty``."""
    D, NK, SIMPLEX, AFFINE, DEGREE, BERNSTEIN = _sizes(cell)

    @njit(cache=True, error_model="numpy")
    def pressures(where, volume, sigma, body, out, dirty):  # pragma: no cover - compiled
        cells, X, K, cell_dofs = where
        bodies = out.shape[1] // 2
        N, G = np.empty(NK), np.empty((NK, D))
        for p in range(len(cells)):
            c = cells[p]
            values_at(X, p, K, c, D, NK, SIMPLEX, AFFINE, DEGREE, BERNSTEIN, N, G)
            t = 0.0
            for j in range(D):
                t += sigma[p, j, j]
            add_patch(out, dirty, (N, NK, cell_dofs, c), body[p], bodies, volume[p], t / D)

    return pressures
