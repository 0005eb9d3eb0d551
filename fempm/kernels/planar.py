r"""The particle passes of :mod:`fempm.kernels.lumped` for triangles and quadrilaterals
(parallelograms, or any with the bilinear map), in scalar code.

The same equations, arguments and results as :func:`fempm.kernels.lumped._scatter_kernel` and
:func:`fempm.kernels.lumped._g2p_kernel` (their dimension-generic loops are the reference,
tested against each other and against the generic step), written out for :math:`d = 2` with
every per-particle quantity (basis values and gradients, :math:`L_p`, :math:`F_p`) in local
scalars: the generic kernels keep them in small scratch arrays, which the compiler must treat
as possibly aliasing the state arrays they write, so every value goes through memory. Here a
G2P pass takes about 30 % less time (1e6 particles on triangles).

The basis on the reference cell (basix's vertex order), :math:`\nabla N_a = \nabla_X \hat N_a K`:

* triangle: :math:`\hat N = (1 - X_0 - X_1,\ X_0,\ X_1)`;
* quadrilateral: :math:`\hat N = ((1-X_0)(1-X_1),\ X_0 (1-X_1),\ (1-X_0) X_1,\ X_0 X_1)`.
"""

from __future__ import annotations

import functools

import numpy as np

from fempm.kernels.bundles import NO_AVERAGE
from fempm.kernels.choice import INLINE
from fempm.kernels.particle_checks import LINEAR_ELASTIC, NEO_HOOKEAN
from fempm.kernels.shape import AVAILABLE

__all__ = ["g2p_kernel", "scatter_kernel"]

if AVAILABLE:
    from numba import njit

    from fempm.kernels.kinematics import add_totals
    from fempm.kernels.multilinear import quad_pull_back
    from fempm.kernels.particle_checks import count_j, stable_time
    from fempm.kernels.patch import add_corners, nodal_ratio
    from fempm.kernels.planar_affine import add_affine, affine_g2p2, carried2, jacobian2, offsets2
    from fempm.kernels.shape import inside_after_pull_back, star_search

    @njit(inline=INLINE)
    def inverse_jacobian(X0, X1, K, c, affine):  # pragma: no cover - compiled
        r"""(k00, k01, k10, k11) of cell ``c`` at the reference point (X0, X1): ``K[c]`` on affine
        cells; not ``affine``, ``K`` holds the vertices of quadrilaterals and the inverse of
        :math:`J(X) = \sum_a x_a \otimes \nabla_X \hat N_a(X)` of the bilinear map is computed."""
        if affine:
            return K[c, 0, 0], K[c, 0, 1], K[c, 1, 0], K[c, 1, 1]
        Z0, Z1 = 1.0 - X0, 1.0 - X1
        j00 = Z1 * (K[c, 1, 0] - K[c, 0, 0]) + X1 * (K[c, 3, 0] - K[c, 2, 0])
        j01 = Z0 * (K[c, 2, 0] - K[c, 0, 0]) + X0 * (K[c, 3, 0] - K[c, 1, 0])
        j10 = Z1 * (K[c, 1, 1] - K[c, 0, 1]) + X1 * (K[c, 3, 1] - K[c, 2, 1])
        j11 = Z0 * (K[c, 2, 1] - K[c, 0, 1]) + X0 * (K[c, 3, 1] - K[c, 1, 1])
        r = 1.0 / (j00 * j11 - j01 * j10)
        return j11 * r, -j01 * r, -j10 * r, j00 * r

    @njit(inline=INLINE)
    def basis(X0, X1, k00, k01, k10, k11, simplex):  # pragma: no cover - compiled
        """(N0..N3, gradients g0x, g0y .. g3x, g3y) at the reference point (X0, X1) with inverse
        Jacobian ``k`` there; on a triangle the fourth is 0."""
        if simplex:
            return (1.0 - X0 - X1, X0, X1, 0.0,
                    -k00 - k10, -k01 - k11, k00, k01, k10, k11, 0.0, 0.0)
        Y0, Y1 = 1.0 - X0, 1.0 - X1
        return (Y0 * Y1, X0 * Y1, Y0 * X1, X0 * X1,
                -Y1 * k00 - Y0 * k10, -Y1 * k01 - Y0 * k11,
                Y1 * k00 - X0 * k10, Y1 * k01 - X0 * k11,
                -X1 * k00 + Y0 * k10, -X1 * k01 + Y0 * k11,
                X1 * k00 + X0 * k10, X1 * k01 + X0 * k11)

    @njit(inline=INLINE)
    def add_pair(out, col, dofs, values, q0, q1, quad):  # pragma: no cover - compiled
        """``out[i_a, col:col+2] += N_a (q0, q1)`` over the cell's ``dofs`` (i0, i1, i2, i3) with
        the basis ``values`` (N0, N1, N2, N3) (the fourth on a quadrilateral only)."""
        i0, i1, i2, i3 = dofs
        N0, N1, N2, N3 = values
        out[i0, col] += N0 * q0
        out[i0, col + 1] += N0 * q1
        out[i1, col] += N1 * q0
        out[i1, col + 1] += N1 * q1
        out[i2, col] += N2 * q0
        out[i2, col + 1] += N2 * q1
        if quad:
            out[i3, col] += N3 * q0
            out[i3, col + 1] += N3 * q1

    @njit(inline=INLINE)
    def add_pressure(sums, p, at, state, quad):  # pragma: no cover - compiled
        r"""F-bar's pressure sums of the next force pass (:func:`fempm.kernels.fbar.pressure_kernel`)
        for particle p where it ends the G2P pass (none for one that left its cell's neighbours):
        :math:`N_a V_p` and :math:`N_a V_p\,\mathrm{tr}\,\sigma_p / 2` into ``sums`` = (the (dofs,
        2 B) sums, their blocks' dirty marks), ``at`` = (cell_dofs, cells, X, whether p moved, the
        dofs i0..i3 and basis values N0..N3 where the pass found it), ``state`` = (volume, sigma,
        body)."""
        out, dirty = sums
        cell_dofs, cells, X, moved, (i0, i1, i2, i3), (N0, N1, N2, N3) = at
        if moved:  # its new cell and reference coordinates
            c = cells[p]
            i0, i1, i2, i3 = cell_dofs[c, 0], cell_dofs[c, 1], cell_dofs[c, 2], cell_dofs[c, 3 if quad else 0]
            N0, N1, N2, N3 = basis(X[p, 0], X[p, 1], 0.0, 0.0, 0.0, 0.0, not quad)[:4]
        volume, sigma, body = state
        add_corners(out, dirty, ((i0, i1, i2, i3), (N0, N1, N2, N3)), body[p], volume[p],
                    0.5 * (sigma[p, 0, 0] + sigma[p, 1, 1]), quad)

    @njit(inline=INLINE)
    def deform(F, p, dt, L00, L01, L10, L11):  # pragma: no cover - compiled
        r""":math:`F_p \leftarrow (I + \Delta t L) F_p`; returns the new entries and
        :math:`J = \det F_p`."""
        f00, f01, f10, f11 = F[p, 0, 0], F[p, 0, 1], F[p, 1, 0], F[p, 1, 1]
        n00 = f00 + dt * L00 * f00 + dt * L01 * f10
        n01 = f01 + dt * L00 * f01 + dt * L01 * f11
        n10 = f10 + dt * L10 * f00 + dt * L11 * f10
        n11 = f11 + dt * L10 * f01 + dt * L11 * f11
        F[p, 0, 0], F[p, 0, 1], F[p, 1, 0], F[p, 1, 1] = n00, n01, n10, n11
        return n00, n01, n10, n11, n00 * n11 - n01 * n10

    @njit(inline=INLINE)
    def patch_at(patch, dofs, values, b, bodies, quad):  # pragma: no cover - compiled
        """F-bar's patch average at a particle of body ``b`` with basis ``values`` (N0..N3) at
        the cell's ``dofs`` (i0..i3; the fourth on a quadrilateral only)."""
        i0, i1, i2, i3 = dofs
        N0, N1, N2, N3 = values
        f = N0 * nodal_ratio(patch, i0, b, bodies) + N1 * nodal_ratio(patch, i1, b, bodies)
        f += N2 * nodal_ratio(patch, i2, b, bodies)
        return f + N3 * nodal_ratio(patch, i3, b, bodies) if quad else f

    @njit(inline=INLINE)
    def increment_measure(F, p, dt, Lp, by_trace):  # pragma: no cover - compiled
        r"""F-bar's measure of the increment (:mod:`fempm.kernels.fbar`): :math:`\Delta\theta_p = \Delta
        t\,\mathrm{tr}(L F_p)` (``by_trace``) or :math:`\Delta J_p = \det(I + \Delta t L)`, ``Lp`` =
        (L00, L01, L10, L11), ``F[p]`` still :math:`F^n_p`."""
        L00, L01, L10, L11 = Lp
        if by_trace:
            return dt * (L00 * F[p, 0, 0] + L01 * F[p, 1, 0] + L10 * F[p, 0, 1] + L11 * F[p, 1, 1])
        return (1.0 + dt * L00) * (1.0 + dt * L11) - (dt * L01) * (dt * L10)

    @njit(inline=INLINE)
    def fbar_deform(F, p, dt, Lp, still, patch):  # pragma: no cover - compiled
        r"""F-bar's kinematics (:mod:`fempm.kernels.fbar`): :math:`F_p \leftarrow \bar F_p = s\,(I +
        \Delta t L_p) F_p + t I` with :math:`s = (\bar f_p / f_p)^{1/2}, t = 0` (a body averaging
        :math:`\det F`) or :math:`s = 1, t = (\bar f_p - f_p) / 2` (averaging :math:`\mathrm{tr}\,F`),
        :math:`f_p` the measure of ``Lp`` (:func:`increment_measure`, as F-bar's first pass; then
        :math:`L_p = 0` for a ``still`` particle of a rigid group) and ``patch`` = (its patch
        average, whether the body averages :math:`\mathrm{tr}\,F`, ``keep_L``); returns the entries
        of :math:`\bar F_p`, its determinant and (with ``keep_L``, else ``Lp``) :math:`\bar L_p`."""
        averaged, by_trace, keep_L = patch
        f = increment_measure(F, p, dt, Lp, by_trace)
        Lp = (0.0, 0.0, 0.0, 0.0) if still else Lp
        Lb = averaged_rate(F, p, dt, Lp, f, averaged, by_trace) if keep_L else Lp  # (from F^n)
        n00, n01, n10, n11, J = deform_averaged(F, p, dt, Lp, f, averaged, by_trace)
        return n00, n01, n10, n11, J, Lb[0], Lb[1], Lb[2], Lb[3]

    @njit(inline=INLINE)
    def deform_averaged(F, p, dt, Lp, f, averaged, by_trace):  # pragma: no cover - compiled
        r""":math:`F_p \leftarrow s (I + \Delta t L) F_p + t I` of F-bar (see :func:`g2p_kernel`) for the
        measure ``f`` and its average; returns the new entries and :math:`J = \det F_p`."""
        L00, L01, L10, L11 = Lp
        s, t = (1.0, 0.5 * (averaged - f)) if by_trace else (np.sqrt(averaged / f), 0.0)
        d00, d01, d10, d11 = 1.0 + dt * L00, dt * L01, dt * L10, 1.0 + dt * L11
        f00, f01, f10, f11 = F[p, 0, 0], F[p, 0, 1], F[p, 1, 0], F[p, 1, 1]
        n00 = s * (d00 * f00 + d01 * f10) + t
        n01 = s * (d00 * f01 + d01 * f11)
        n10 = s * (d10 * f00 + d11 * f10)
        n11 = s * (d10 * f01 + d11 * f11) + t
        F[p, 0, 0], F[p, 0, 1], F[p, 1, 0], F[p, 1, 1] = n00, n01, n10, n11
        return n00, n01, n10, n11, n00 * n11 - n01 * n10

    @njit(inline=INLINE)
    def averaged_rate(F, p, dt, Lp, f, averaged, by_trace):  # pragma: no cover - compiled
        r""":math:`\bar L` with :math:`(I + \Delta t \bar L) F^n_p = \bar F_p` (``F[p]`` still :math:`F^n_p`):
        :math:`(s (I + \Delta t L) - I) / \Delta t`, or :math:`L + t (F^n_p)^{-1} / \Delta t` for a body
        averaging :math:`\mathrm{tr}\,F`."""
        L00, L01, L10, L11 = Lp
        if not by_trace:
            s = np.sqrt(averaged / f)
            return ((s * (1.0 + dt * L00) - 1.0) / dt, s * L01, s * L10, (s * (1.0 + dt * L11) - 1.0) / dt)
        f00, f01, f10, f11 = F[p, 0, 0], F[p, 0, 1], F[p, 1, 0], F[p, 1, 1]
        q = 0.5 * (averaged - f) / dt / (f00 * f11 - f01 * f10)
        return L00 + q * f11, L01 - q * f01, L10 - q * f10, L11 + q * f00

    @njit(inline=INLINE)
    def law_stress(sigma, p, code, lam, mu, n00, n01, n10, n11, J):  # pragma: no cover - compiled
        r"""``sigma[p]`` of the compiled law ``code`` (else left as it is) for
        :math:`F = [[n_{00}, n_{01}], [n_{10}, n_{11}]]`, :math:`J = \det F > 0`."""
        if code == NEO_HOOKEAN:
            inv = 1.0 / J
            vol = lam * np.log(J)
            s01 = mu * (n00 * n10 + n01 * n11) * inv
            sigma[p, 0, 0] = (mu * (n00 * n00 + n01 * n01 - 1.0) + vol) * inv
            sigma[p, 0, 1] = s01
            sigma[p, 1, 0] = s01
            sigma[p, 1, 1] = (mu * (n10 * n10 + n11 * n11 - 1.0) + vol) * inv
        elif code == LINEAR_ELASTIC:
            tr = (n00 - 1.0) + (n11 - 1.0)
            s01 = 2.0 * mu * (0.5 * (n01 + n10))
            sigma[p, 0, 0] = lam * tr + 2.0 * mu * (n00 - 1.0)
            sigma[p, 0, 1] = s01
            sigma[p, 1, 0] = s01
            sigma[p, 1, 1] = lam * tr + 2.0 * mu * (n11 - 1.0)


@functools.cache
def scatter_kernel(simplex: bool, affine: bool, with_mass: bool, with_momentum: bool, with_force: bool, with_dt: bool,
                   has_fext: bool, bound: bool, grouped: bool = False, with_gradient: bool = False, kind: int = 0,
                   averaged: bool = False):
    """:func:`fempm.kernels.lumped._scatter_kernel` for ``triangle`` (``simplex``) or
    ``quadrilateral`` cells, ``affine`` or multilinear (``kind``, APIC or TPIC: affine cells;
    :mod:`fempm.kernels.planar_affine`; ``averaged``: F-bar's averaged pressure in the force)."""
    KIND = kind
    CV = 1 if with_mass else 0
    CF = CV + (2 if with_momentum else 0)
    CG = CF + (2 if with_force else 0)
    QUAD = not simplex

    @njit(cache=True, error_model="numpy")
    def scatter(where, state, laws, forces, out, stable, groups, carried=None):  # pragma: no cover
        cells, X, K, cell_dofs = where
        mass, v, volume, sigma, body = state.mass, state.v, state.volume, state.sigma, state.body
        C, spin = (carried.C, carried.spin) if KIND else (np.empty((0, 2, 2)), np.empty((0, 1)))
        modulus, g, fext, h, c = laws.modulus, forces.g, forces.fext, stable.h, stable.c
        group, stride, patch = groups.group, groups.stride, forces.patch
        bodies = patch.shape[1] // 2
        best = 0.0 if bound else np.inf
        for p in range(len(cells)):
            cp = cells[p]
            X0, X1 = X[p, 0], X[p, 1]
            k00, k01, k10, k11 = inverse_jacobian(X0, X1, K, cp, affine)
            N0, N1, N2, N3, g0x, g0y, g1x, g1y, g2x, g2y, g3x, g3y = basis(X0, X1, k00, k01, k10, k11, simplex)
            m = mass[p]
            V = volume[p]
            v0, v1 = v[p, 0], v[p, 1]
            speed = v0 * v0 + v1 * v1
            if with_dt:
                best = stable_time(best, bound, m, V, speed, modulus[body[p]], c, p, h[cp])
            i0, i1, i2 = cell_dofs[cp, 0], cell_dofs[cp, 1], cell_dofs[cp, 2]
            i3 = cell_dofs[cp, 3] if QUAD else i0
            o = group[p] * stride if grouped else 0
            if with_mass:
                out[i0, o] += N0 * m
                out[i1, o] += N1 * m
                out[i2, o] += N2 * m
                if QUAD:
                    out[i3, o] += N3 * m
            if with_momentum and KIND:
                j = jacobian2((k00, k01, k10, k11))
                r = offsets2(X0, X1, j, simplex)
                c00, c01, c10, c11 = carried2(C, spin, p, (X0, X1), j, simplex, KIND)
                add_affine(out, o + CV, (i0, i1, i2, i3), (N0, N1, N2, N3), (m * v0, m * v1), (m * c00, m * c01, m * c10, m * c11), r, QUAD)
            elif with_momentum:
                add_pair(out, o + CV, (i0, i1, i2, i3), (N0, N1, N2, N3), m * v0, m * v1, QUAD)
            if with_force:
                fe0, fe1 = m * g[0], m * g[1]
                if has_fext:
                    fe0 += fext[p, 0]
                    fe1 += fext[p, 1]
                s00, s01, s10, s11 = sigma[p, 0, 0], sigma[p, 0, 1], sigma[p, 1, 0], sigma[p, 1, 1]
                if averaged:  # F-bar: the patch-averaged pressure
                    b = body[p]
                    t = (N0 * nodal_ratio(patch, i0, b, bodies) + N1 * nodal_ratio(patch, i1, b, bodies) + N2 * nodal_ratio(patch, i2, b, bodies)
                         + (N3 * nodal_ratio(patch, i3, b, bodies) if QUAD else 0.0)) - 0.5 * (s00 + s11)
                    s00, s11 = s00 + t, s11 + t
                f = o + CF
                out[i0, f] += N0 * fe0 - V * (s00 * g0x + s01 * g0y)
                out[i0, f + 1] += N0 * fe1 - V * (s10 * g0x + s11 * g0y)
                out[i1, f] += N1 * fe0 - V * (s00 * g1x + s01 * g1y)
                out[i1, f + 1] += N1 * fe1 - V * (s10 * g1x + s11 * g1y)
                out[i2, f] += N2 * fe0 - V * (s00 * g2x + s01 * g2y)
                out[i2, f + 1] += N2 * fe1 - V * (s10 * g2x + s11 * g2y)
                if QUAD:
                    out[i3, f] += N3 * fe0 - V * (s00 * g3x + s01 * g3y)
                    out[i3, f + 1] += N3 * fe1 - V * (s10 * g3x + s11 * g3y)
            if with_gradient:  # sum_p M_p grad N_ip
                f = o + CG
                out[i0, f] += m * g0x
                out[i0, f + 1] += m * g0y
                out[i1, f] += m * g1x
                out[i1, f + 1] += m * g1y
                out[i2, f] += m * g2x
                out[i2, f + 1] += m * g2y
                if QUAD:
                    out[i3, f] += m * g3x
                    out[i3, f + 1] += m * g3y
        return 1.0 / np.sqrt(2.0 * best) if bound else best

    return scatter


@functools.cache
def g2p_kernel(simplex: bool, affine: bool, blend: bool, kinematics: bool, move: bool, remap: bool,
               totals: bool = False, grouped: bool = False, kind: int = 0, remap_affine: bool = False,
               averaged: bool = False, pressures: bool = False):
    """:func:`fempm.kernels.lumped._g2p_kernel` for ``triangle`` (``simplex``) or
    ``quadrilateral`` cells, ``affine`` or multilinear (``kind``, APIC or TPIC, in a blend pass:
    affine cells; :mod:`fempm.kernels.planar_affine`); ``averaged``: F-bar's kinematics
    (:func:`fbar_deform`, the ``average`` bundle), with ``pressures`` the next force pass's sums
    (:func:`add_pressure`)."""
    QUAD, KIND = not simplex, kind

    @njit(cache=True, error_model="numpy")
    def g2p_update(where, grid, state, laws, moves, outputs, groups, carried=None, average=None):  # pragma: no cover
        cells, X, K, cell_dofs = where
        patch, by_trace, bodies, pressure_sums, dirty = average if averaged else NO_AVERAGE
        C, spin, va, weak = ((carried.C, carried.spin, carried.v, carried.weak) if KIND else
                             (np.empty((0, 2, 2)), np.empty((0, 1)), np.empty((0, 2)), np.empty(0, np.uint8)))
        (v_new, v_old, flip, dt, by_particle), (x, v, F, volume0, volume, sigma, body, mass) = grid, state
        law, lam, mu, x0, tol, left, star = laws.law, laws.lam, laws.mu, moves.x0, moves.tol, moves.left, moves.star
        L, mom, sums, group, rigid = outputs.L, outputs.mom, outputs.sums, groups.group, groups.rigid
        n, keep_L = len(cells), L.shape[0] == len(cells)
        nonfinite_j, inverted, jmin, jmax, nonfinite, acc = 0, 0, np.inf, -np.inf, 0, np.zeros(5)  # checks, sums
        for p in range(n):
            c = cells[p]
            X0, X1 = X[p, 0], X[p, 1]
            k00, k01, k10, k11 = inverse_jacobian(X0, X1, K, c, affine)
            N0, N1, N2, N3, g0x, g0y, g1x, g1y, g2x, g2y, g3x, g3y = basis(X0, X1, k00, k01, k10, k11, simplex)
            i0, i1, i2, i3 = cell_dofs[c, 0], cell_dofs[c, 1], cell_dofs[c, 2], cell_dofs[c, 3 if QUAD else 0]
            o, o1, still = (group[p] * 2, group[p] * 2 + 1, rigid[group[p]]) if grouped else (0, 1, False)  # still: rigid
            a0, b0, a1, b1, a2, b2 = v_new[i0, o], v_new[i0, o1], v_new[i1, o], v_new[i1, o1], v_new[i2, o], v_new[i2, o1]
            vg0, vg1 = N0 * a0 + N1 * a1 + N2 * a2, N0 * b0 + N1 * b1 + N2 * b2
            if QUAD:
                a3, b3 = v_new[i3, o], v_new[i3, o1]
                vg0, vg1 = vg0 + N3 * a3, vg1 + N3 * b3
            if blend and not still:
                dv0 = N0 * (a0 - v_old[i0, o]) + N1 * (a1 - v_old[i1, o]) + N2 * (a2 - v_old[i2, o])
                dv1 = N0 * (b0 - v_old[i0, o1]) + N1 * (b1 - v_old[i1, o1]) + N2 * (b2 - v_old[i2, o1])
                if QUAD:
                    dv0, dv1 = dv0 + N3 * (a3 - v_old[i3, o]), dv1 + N3 * (b3 - v_old[i3, o1])
                v[p, 0], v[p, 1] = flip * (v[p, 0] + dv0) + (1.0 - flip) * vg0, flip * (v[p, 1] + dv1) + (1.0 - flip) * vg1
            if KIND:  # the affine state (C = L, APIC's spin; the cutoff) and with the lumped mass the re-map with it
                affine_g2p2(p, (X0, X1, (k00, k01, k10, k11), simplex, QUAD), ((N0, N1, N2, N3 if QUAD else 0.0), (
                    a0, a1, a2, a3 if QUAD else 0.0), (b0, b1, b2, b3 if QUAD else 0.0), (g0x, g0y, g1x, g1y, g2x, g2y, g3x, g3y),
                    (i0, i1, i2, i3)), (C, spin, mom, o, mass, v), (va, weak, o1), remap and remap_affine, KIND)
            if remap and not (KIND and remap_affine):  # MUSL: the blended momenta back to the grid, in the same pass
                add_pair(mom, o, (i0, i1, i2, i3), (N0, N1, N2, N3), mass[p] * v[p, 0], mass[p] * v[p, 1], QUAD)
            if kinematics:
                L00, L01 = a0 * g0x + a1 * g1x + a2 * g2x, a0 * g0y + a1 * g1y + a2 * g2y
                L10, L11 = b0 * g0x + b1 * g1x + b2 * g2x, b0 * g0y + b1 * g1y + b2 * g2y
                if QUAD:
                    L00, L01, L10, L11 = L00 + a3 * g3x, L01 + a3 * g3y, L10 + b3 * g3x, L11 + b3 * g3y
                b = body[p]
                if averaged:  # F-bar: the measure's patch average
                    n00, n01, n10, n11, J, L00, L01, L10, L11 = fbar_deform(F, p, dt, (L00, L01, L10, L11), still, (
                        patch_at(patch, (i0, i1, i2, i3), (N0, N1, N2, N3), b, bodies, QUAD), by_trace[b], keep_L))
                else:
                    L00, L01, L10, L11 = (0.0, 0.0, 0.0, 0.0) if still else (L00, L01, L10, L11)
                    n00, n01, n10, n11, J = deform(F, p, dt, L00, L01, L10, L11)
                if keep_L:
                    L[p, 0, 0], L[p, 0, 1], L[p, 1, 0], L[p, 1, 1] = L00, L01, L10, L11
                volume[p] = J * volume0[p]
                ok, nonfinite_j, inverted, jmin, jmax = count_j(J, nonfinite_j, inverted, jmin, jmax)
                if ok:
                    law_stress(sigma, p, law[b], lam[b], mu[b], n00, n01, n10, n11, J)
            if move:
                u0, u1 = (dt * v[p, 0], dt * v[p, 1]) if by_particle or still else (dt * vg0, dt * vg1)
                x[p, 0], x[p, 1] = y0, y1 = x[p, 0] + u0, x[p, 1] + u1
                if not (np.isfinite(y0) and np.isfinite(y1) and np.isfinite(v[p, 0] * v[p, 0] + v[p, 1] * v[p, 1])):
                    nonfinite += 1  # x or v (v.v: the kinetic energy); the compiled laws' stress is finite where J is
                if not affine:  # Newton from the first step X + K(X) u (K of the basis above), its size the seed's
                    X[p, 0], X[p, 1] = X0 + k00 * u0 + k01 * u1, X1 + k10 * u0 + k11 * u1
                out = not (inside_after_pull_back(x, p, x0, K, c, simplex, 2, tol, X, affine) if affine else
                           quad_pull_back(x, p, K, c, tol, X, max(abs(X[p, 0] - X0), abs(X[p, 1] - X1))))
                # the neighbours, while in cache (written out: through a helper the pass took 1.8x as long)
                e = star_search(x, p, x0, K, c, star, simplex, 2, tol, X, affine) if out else c
                cells[p], left[p] = (c, True) if e < 0 else (e, False)
            if pressures and not (move and left[p]):  # F-bar (a kinematics pass): the next force pass's sums
                add_pressure((pressure_sums, dirty), p, (cell_dofs, cells, X, move, (i0, i1, i2, i3), (N0, N1, N2, N3)),
                             (volume, sigma, body), QUAD)
            if totals:
                add_totals(acc, p, mass, v, F, volume0, law[body[p]], lam[body[p]], mu[body[p]], 2)
        if totals:
            sums[:] = acc
        return nonfinite_j, inverted, jmin, jmax, nonfinite

    return g2p_update
