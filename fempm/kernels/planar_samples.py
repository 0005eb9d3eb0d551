r"""The sample passes of :mod:`fempm.kernels.samples` for triangles and quadrilaterals, in
scalar code and sample by sample.

The same equations, arguments and results as :func:`fempm.kernels.samples._scatter_kernel` and
:func:`fempm.kernels.samples._g2p_kernel` (the reference they are tested against), written out
for :math:`d = 2` in local scalars, as :mod:`fempm.kernels.planar` writes the point passes, and
summed sample by sample instead of cell by cell. With CPDI's gradient weights :math:`g_{pq}`
the averaged gradient factorises over the samples:

.. math::
    \sum_i v_i \otimes \langle \nabla N_i \rangle_p = \sum_q v(y_{pq}) \otimes g_{pq},
    \qquad v(y_{pq}) = \sum_a N_a(y_{pq})\, v_{d(pq, a)},

and a node's force share is :math:`N_a(y_{pq}) (w_{pq} f^{ext}_p - V_p \sigma_p g_{pq})`: the
per-node work is that of the point pass, with no :math:`d \times d` product per node. Gauss GIMP
and exact GIMP (``grad_from_values``) weight each sample's point-pass terms by :math:`w_{pq}`.
"""

from __future__ import annotations

import functools

import numpy as np

from fempm.kernels.choice import INLINE
from fempm.kernels.shape import AVAILABLE

__all__ = ["g2p_kernel", "mass_apply_kernel", "scatter_kernel"]

if AVAILABLE:
    from numba import njit

    from fempm.kernels.corners import corner_geometry
    from fempm.kernels.fmpm import add_column, coupled
    from fempm.kernels.kinematics import add_totals
    from fempm.kernels.particle_checks import count_j, stable_time
    from fempm.kernels.planar import add_pair, basis, deform, inverse_jacobian, law_stress
    from fempm.kernels.shape import inside_after_pull_back, star_search

    @njit(inline=INLINE)
    def corner_inverse(F, lp, p):  # pragma: no cover - compiled
        r""":math:`R^{-1}` of CPDI1's :math:`R = F_p \operatorname{diag}(\ell_p)` (:mod:`fempm.kernels.cpdi1`)."""
        a, b = F[p, 0, 0] * lp[p, 0], F[p, 0, 1] * lp[p, 1]
        c, d = F[p, 1, 0] * lp[p, 0], F[p, 1, 1] * lp[p, 1]
        det = a * d - b * c
        return d / det, -b / det, -c / det, a / det

    @njit(inline=INLINE)
    def corner_weight(r00, r01, r10, r11, signs, q, share):  # pragma: no cover - compiled
        """CPDI1's gradient weight :math:`Q^{-1} R^{-T} s_q` of corner ``q``."""
        s0, s1 = signs[q, 0], signs[q, 1]
        return share * (r00 * s0 + r10 * s1), share * (r01 * s0 + r11 * s1)

    @njit(inline=INLINE)
    def add_momentum(p, sc, Y, w, cell_dofs, m0, m1, mom, simplex, grad_from_values,
                     corners):  # pragma: no cover - compiled
        r"""MUSL's re-map of particle ``p``'s blended momentum ``(m0, m1)`` over its samples,
        :math:`m_i \mathrel{+}= \sum_q w_{pq} N_i(y_{pq}) M_p v_p` (inlined into the G2P pass)."""
        QUAD = not simplex
        Q = sc.shape[1]
        for q in range(Q):
            wq = 1.0 / Q if corners else w[p, q]
            if grad_from_values and wq == 0.0:
                continue
            r = p * Q + q
            cq = sc[p, q]
            N0, N1, N2, N3 = basis(Y[r, 0], Y[r, 1], 0.0, 0.0, 0.0, 0.0, simplex)[:4]
            i0, i1, i2 = cell_dofs[cq, 0], cell_dofs[cq, 1], cell_dofs[cq, 2]
            i3 = cell_dofs[cq, 3] if QUAD else i0
            add_pair(mom, 0, (i0, i1, i2, i3), (N0, N1, N2, N3), wq * m0, wq * m1, QUAD)

    @njit(inline=INLINE)
    def sample(p, q, Q, sc, Y, w, cell_dofs, simplex, corners):  # pragma: no cover - compiled
        """Sample ``q`` of particle ``p``: its weight (0: none), basis values and cell's dofs."""
        wq = 1.0 / Q if corners else w[p, q]
        r, cq = p * Q + q, sc[p, q]
        N0, N1, N2, N3 = basis(Y[r, 0], Y[r, 1], 0.0, 0.0, 0.0, 0.0, simplex)[:4]
        i0, i1, i2 = cell_dofs[cq, 0], cell_dofs[cq, 1], cell_dofs[cq, 2]
        return wq, N0, N1, N2, N3, i0, i1, i2, cell_dofs[cq, 3] if not simplex else i0

    @njit(inline=INLINE)
    def gather(p, samples, v_new, v_old, at, simplex, affine, grad_from_values, corners, blend, kinematics,
               track):  # pragma: no cover - compiled
        """Particle ``p``'s grid velocity, FLIP increment and velocity gradient summed over its
        samples, (vg0, vg1, dv0, dv1, L00, L01, L10, L11) (inlined into the G2P pass, where the
        flags are the pass's constants); with ``track`` the grid velocity at each sample into
        ``at[p, q]`` (``samples``: :class:`~fempm.kernels.bundles.Samples`)."""
        sc, Y, w, gw, Fw, lp, signs, K, cell_dofs = samples
        QUAD = not simplex
        Q = sc.shape[1]
        share = 1.0 / Q
        vg0, vg1, dv0, dv1 = 0.0, 0.0, 0.0, 0.0
        L00, L01, L10, L11 = 0.0, 0.0, 0.0, 0.0
        if corners:  # of F before this pass updates it
            r00, r01, r10, r11 = corner_inverse(Fw, lp, p)
        for q in range(Q):
            wq = share if corners else w[p, q]
            if grad_from_values and wq == 0.0:
                continue
            r = p * Q + q
            cq = sc[p, q]
            X0, X1 = Y[r, 0], Y[r, 1]
            k00, k01, k10, k11 = inverse_jacobian(X0, X1, K, cq, affine)
            N0, N1, N2, N3, g0x, g0y, g1x, g1y, g2x, g2y, g3x, g3y = basis(X0, X1, k00, k01, k10, k11, simplex)
            i0, i1, i2 = cell_dofs[cq, 0], cell_dofs[cq, 1], cell_dofs[cq, 2]
            i3 = cell_dofs[cq, 3] if QUAD else i0
            a0, b0, a1, b1 = v_new[i0, 0], v_new[i0, 1], v_new[i1, 0], v_new[i1, 1]
            a2, b2 = v_new[i2, 0], v_new[i2, 1]
            u0 = N0 * a0 + N1 * a1 + N2 * a2
            u1 = N0 * b0 + N1 * b1 + N2 * b2
            if QUAD:
                a3, b3 = v_new[i3, 0], v_new[i3, 1]
                u0 += N3 * a3
                u1 += N3 * b3
            vg0 += wq * u0
            vg1 += wq * u1
            if track:
                at[p, q, 0], at[p, q, 1] = u0, u1
            if blend:
                e0 = N0 * (a0 - v_old[i0, 0]) + N1 * (a1 - v_old[i1, 0]) + N2 * (a2 - v_old[i2, 0])
                e1 = N0 * (b0 - v_old[i0, 1]) + N1 * (b1 - v_old[i1, 1]) + N2 * (b2 - v_old[i2, 1])
                if QUAD:
                    e0 += N3 * (a3 - v_old[i3, 0])
                    e1 += N3 * (b3 - v_old[i3, 1])
                dv0 += wq * e0
                dv1 += wq * e1
            if kinematics and grad_from_values:
                l00 = a0 * g0x + a1 * g1x + a2 * g2x
                l01 = a0 * g0y + a1 * g1y + a2 * g2y
                l10 = b0 * g0x + b1 * g1x + b2 * g2x
                l11 = b0 * g0y + b1 * g1y + b2 * g2y
                if QUAD:
                    l00 += a3 * g3x
                    l01 += a3 * g3y
                    l10 += b3 * g3x
                    l11 += b3 * g3y
                L00 += wq * l00
                L01 += wq * l01
                L10 += wq * l10
                L11 += wq * l11
            elif kinematics:  # v(y_q) (x) g_q
                if corners:
                    t0, t1 = corner_weight(r00, r01, r10, r11, signs, q, share)
                else:
                    t0, t1 = gw[p, q, 0], gw[p, q, 1]
                L00 += u0 * t0
                L01 += u0 * t1
                L10 += u1 * t0
                L11 += u1 * t1
        return vg0, vg1, dv0, dv1, L00, L01, L10, L11


@functools.cache
def scatter_kernel(simplex: bool, affine: bool, grad_from_values: bool, corners: bool, with_mass: bool,
                   with_momentum: bool, with_force: bool, with_dt: bool, has_fext: bool, bound: bool):
    """:func:`fempm.kernels.samples._scatter_kernel` for ``triangle`` (``simplex``) or
    ``quadrilateral`` cells, ``affine`` or multilinear."""
    CV = 1 if with_mass else 0
    CF = CV + (2 if with_momentum else 0)
    QUAD = not simplex

    @njit(cache=True, error_model="numpy")
    def scatter(where, samples, state, laws, forces, out, stable):  # pragma: no cover
        cells = where.cells
        sc, Y, w, gw, Fw, lp, signs, K, cell_dofs = samples
        mass, v, volume, sigma, body = state.mass, state.v, state.volume, state.sigma, state.body
        modulus, g, fext, h, c = laws.modulus, forces.g, forces.fext, stable.h, stable.c
        Q = sc.shape[1]
        share = 1.0 / Q
        best = 0.0 if bound else np.inf
        for p in range(len(cells)):
            m = mass[p]
            V = volume[p]
            v0, v1 = v[p, 0], v[p, 1]
            if with_dt:
                best = stable_time(best, bound, m, V, v0 * v0 + v1 * v1, modulus[body[p]], c, p, h[cells[p]])
            fe0, fe1 = m * g[0], m * g[1]
            if has_fext:
                fe0 += fext[p, 0]
                fe1 += fext[p, 1]
            s00, s01, s10, s11 = sigma[p, 0, 0], sigma[p, 0, 1], sigma[p, 1, 0], sigma[p, 1, 1]
            if corners:
                r00, r01, r10, r11 = corner_inverse(Fw, lp, p)
            for q in range(Q):
                wq = share if corners else w[p, q]
                if grad_from_values and wq == 0.0:
                    continue  # a sample of no weight (GIMP's cut or unused samples)
                r = p * Q + q
                cq = sc[p, q]
                X0, X1 = Y[r, 0], Y[r, 1]
                k00, k01, k10, k11 = inverse_jacobian(X0, X1, K, cq, affine)
                N0, N1, N2, N3, g0x, g0y, g1x, g1y, g2x, g2y, g3x, g3y = basis(X0, X1, k00, k01, k10, k11, simplex)
                i0, i1, i2 = cell_dofs[cq, 0], cell_dofs[cq, 1], cell_dofs[cq, 2]
                i3 = cell_dofs[cq, 3] if QUAD else i0
                if with_mass:
                    out[i0, 0] += N0 * (wq * m)
                    out[i1, 0] += N1 * (wq * m)
                    out[i2, 0] += N2 * (wq * m)
                    if QUAD:
                        out[i3, 0] += N3 * (wq * m)
                if with_momentum:
                    add_pair(out, CV, (i0, i1, i2, i3), (N0, N1, N2, N3), wq * m * v0, wq * m * v1, QUAD)
                if with_force and grad_from_values:  # w_q (N_a f - V sigma grad N_a)
                    a0, a1 = wq * fe0, wq * fe1
                    b00, b01, b10, b11 = wq * V * s00, wq * V * s01, wq * V * s10, wq * V * s11
                    out[i0, CF] += N0 * a0 - (b00 * g0x + b01 * g0y)
                    out[i0, CF + 1] += N0 * a1 - (b10 * g0x + b11 * g0y)
                    out[i1, CF] += N1 * a0 - (b00 * g1x + b01 * g1y)
                    out[i1, CF + 1] += N1 * a1 - (b10 * g1x + b11 * g1y)
                    out[i2, CF] += N2 * a0 - (b00 * g2x + b01 * g2y)
                    out[i2, CF + 1] += N2 * a1 - (b10 * g2x + b11 * g2y)
                    if QUAD:
                        out[i3, CF] += N3 * a0 - (b00 * g3x + b01 * g3y)
                        out[i3, CF + 1] += N3 * a1 - (b10 * g3x + b11 * g3y)
                elif with_force:  # N_a (w_q f - V sigma g_q)
                    if corners:
                        t0, t1 = corner_weight(r00, r01, r10, r11, signs, q, share)
                    else:
                        t0, t1 = gw[p, q, 0], gw[p, q, 1]
                    f0 = wq * fe0 - V * (s00 * t0 + s01 * t1)
                    f1 = wq * fe1 - V * (s10 * t0 + s11 * t1)
                    add_pair(out, CF, (i0, i1, i2, i3), (N0, N1, N2, N3), f0, f1, QUAD)
        return 1.0 / np.sqrt(2.0 * best) if bound else best

    return scatter


@functools.cache
def g2p_kernel(simplex: bool, affine: bool, grad_from_values: bool, corners: bool, blend: bool, kinematics: bool,
               move: bool, remap: bool, totals: bool, track: bool = False):
    """:func:`fempm.kernels.samples._g2p_kernel` for ``triangle`` (``simplex``) or
    ``quadrilateral`` cells, ``affine`` or multilinear. With ``track`` (CPDI2, moving) the
    pass also moves the domains' corners ``yc`` (n, Q, 2) with the grid velocity at them into
    ``moved``, puts their weights (:func:`fempm.kernels.corners.corner_geometry`) into ``w``
    and ``gw`` (each particle's, once the pass has read them), moves each particle to its domain's centroid
    with the domain's volume, locates the moved corners in ``sc`` and ``Y`` (as
    :func:`fempm.kernels.sample_location.locate_samples`, over the first ``sample_cells`` cells; -1
    where the search fails), and counts the twisted domains in ``bad[0]`` and the corners not
    found in ``bad[1]``."""
    @njit(cache=True, error_model="numpy")
    def g2p_update(where, samples, grid, state, laws, moves, outputs, tracked):  # pragma: no cover
        cells, X = where.cells, where.X
        sc, Y, w, gw, Fw, lp, signs, K, cell_dofs = samples
        v_new, v_old, flip, dt, by_particle = grid
        x, v, F, volume0, volume, sigma, body, mass = state
        law, lam, mu = laws.law, laws.lam, laws.mu
        x0, tol, left, star = moves
        c2v, v_offsets, v_cells = star.c2v, star.v_offsets, star.v_cells  # (the corners search sample_cells)
        L, mom, sums = outputs
        yc, moved, bad, sample_cells = tracked
        n, keep_L = len(cells), L.shape[0] == len(cells)
        Q = sc.shape[1]
        ys = moved.reshape((moved.shape[0] * moved.shape[1], 2))  # the moved corners, one a row
        nonfinite_j, inverted, jmin, jmax, nonfinite = 0, 0, np.inf, -np.inf, 0  # the pass's checks
        acc = np.zeros(5)  # the state's sums (totals)
        for p in range(n):
            vg0, vg1, dv0, dv1, L00, L01, L10, L11 = gather(p, samples, v_new, v_old, moved, simplex, affine,
                                                            grad_from_values, corners, blend, kinematics, track)
            if blend:
                v[p, 0] = flip * (v[p, 0] + dv0) + (1.0 - flip) * vg0
                v[p, 1] = flip * (v[p, 1] + dv1) + (1.0 - flip) * vg1
            if remap:  # MUSL: the blended momenta back to the grid
                add_momentum(p, sc, Y, w, cell_dofs, mass[p] * v[p, 0], mass[p] * v[p, 1], mom, simplex,
                             grad_from_values, corners)
            if kinematics:
                n00, n01, n10, n11, J = deform(F, p, dt, L00, L01, L10, L11)
                if keep_L:
                    L[p, 0, 0], L[p, 0, 1], L[p, 1, 0], L[p, 1, 1] = L00, L01, L10, L11
                volume[p] = J * volume0[p]
                b = body[p]
                ok, nonfinite_j, inverted, jmin, jmax = count_j(J, nonfinite_j, inverted, jmin, jmax)
                if ok:
                    law_stress(sigma, p, law[b], lam[b], mu[b], n00, n01, n10, n11, J)
            if move and track:  # the corners with the grid velocity at them (gathered), the particle to the centroid
                for q in range(yc.shape[1]):
                    moved[p, q, 0] = yc[p, q, 0] + dt * moved[p, q, 0]
                    moved[p, q, 1] = yc[p, q, 1] + dt * moved[p, q, 1]
                volume[p], y0, y1, twisted = corner_geometry(moved, p, w, gw)
                if twisted:
                    bad[0] += 1
            elif move:
                y0 = x[p, 0] + dt * (v[p, 0] if by_particle else vg0)
                y1 = x[p, 1] + dt * (v[p, 1] if by_particle else vg1)
            if move:
                x[p, 0], x[p, 1] = y0, y1
                if not (np.isfinite(y0) and np.isfinite(y1) and np.isfinite(v[p, 0] * v[p, 0] + v[p, 1] * v[p, 1])):
                    nonfinite += 1
                c = cells[p]
                out = not inside_after_pull_back(x, p, x0, K, c, simplex, 2, tol, X, affine)
                if out:
                    e = star_search(x, p, x0, K, c, star, simplex, 2, tol, X, affine)
                    out = e < 0
                    cells[p] = c if out else e
                left[p] = out
            if move and track:  # each moved corner: in its cell, the particle's or the particle's vertex star
                for q in range(Q):
                    r, e = p * Q + q, sc[p, q]
                    if e >= 0 and inside_after_pull_back(ys, r, x0, K, e, simplex, 2, tol, Y, affine):
                        continue
                    c = cells[p]
                    if e != c and inside_after_pull_back(ys, r, x0, K, c, simplex, 2, tol, Y, affine):
                        sc[p, q] = c
                    else:
                        e = star_search(ys, r, x0, K, c, (c2v, v_offsets, v_cells, sample_cells), simplex, 2, tol, Y,
                                        affine)
                        sc[p, q] = e
                        if e < 0:
                            bad[1] += 1
            if totals:
                add_totals(acc, p, mass, v, F, volume0, law[body[p]], lam[body[p]], mu[body[p]], 2)
        if totals:
            sums[:] = acc
        return nonfinite_j, inverted, jmin, jmax, nonfinite

    return g2p_update






@functools.cache
def mass_apply_kernel(simplex: bool, grad_from_values: bool, corners: bool):
    r""":func:`fempm.kernels.samples.kernels_for`'s ``mass_apply`` (FMPM's
    :math:`(M_C y)_i = \sum_p M_p \langle N_i \rangle_p \sum_j \langle N_j \rangle_p y_j`)
    for ``triangle`` (``simplex``) or ``quadrilateral`` cells, sample by sample and two columns
    of ``y`` at a time (an even number), the values alone."""
    QUAD = not simplex

    @njit(cache=True, error_model="numpy")
    def mass_apply(where, samples, mass, y, lump, out):  # pragma: no cover
        cells = where.cells
        sc, Y, w, cell_dofs = samples.sc, samples.Y, samples.w, samples.cell_dofs
        Q = sc.shape[1]
        k = y.shape[1]
        lumping = lump.shape[0] > 0
        u = np.empty(k + 1)  # <N_j> y_j over the coupled dofs, and <N_j> 1_l
        for p in range(len(cells)):
            u[:] = 0.0
            for q in range(Q):
                wq, N0, N1, N2, N3, i0, i1, i2, i3 = sample(p, q, Q, sc, Y, w, cell_dofs, simplex, corners)
                if grad_from_values and wq == 0.0:
                    continue
                e0, e1, e2, e3 = wq * N0, wq * N1, wq * N2, wq * N3
                if lumping:
                    e0, e1, e2, e3 = coupled(lump, i0, i1, i2, i3, e0, e1, e2, e3, QUAD)
                    u[k] += wq * (N0 + N1 + N2 + (N3 if QUAD else 0.0)) - (e0 + e1 + e2 + (e3 if QUAD else 0.0))
                for j in range(k):
                    t = e0 * y[i0, j] + e1 * y[i1, j] + e2 * y[i2, j]
                    u[j] += t + e3 * y[i3, j] if QUAD else t
            m = mass[p]
            for q in range(Q):
                wq, N0, N1, N2, N3, i0, i1, i2, i3 = sample(p, q, Q, sc, Y, w, cell_dofs, simplex, corners)
                if grad_from_values and wq == 0.0:
                    continue
                s = wq * m
                for j in range(0, k, 2):
                    add_pair(out, j, (i0, i1, i2, i3), (N0, N1, N2, N3), s * u[j], s * u[j + 1], QUAD)
                if lumping:
                    add_column(out, k, i0, i1, i2, i3, N0, N1, N2, N3, s * u[k], QUAD)

    return mass_apply
