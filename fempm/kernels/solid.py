r"""The particle passes of :mod:`fempm.kernels.lumped` for tetrahedra and affine hexahedra
(parallelepipeds), with the per-particle quantities in local scalars.

The same equations, arguments and results as :func:`fempm.kernels.lumped._scatter_kernel` and
:func:`fempm.kernels.lumped._g2p_kernel` (their dimension-generic loops are the reference,
tested against these to round-off), for :math:`d = 3`: the generic kernels keep the basis
values and gradients, :math:`L_p` and the stress in small scratch arrays, which the compiler
must treat as possibly aliasing the nodal and state arrays they write, so every value goes
through memory; here each node's value and gradient are computed where they are used
(:func:`node`) and :math:`L_p`, :math:`F_p` are scalars, as :mod:`fempm.kernels.planar` does
in 2D.

The basis on the reference cell (basix's vertex order), :math:`\nabla N_a = \nabla_X \hat N_a K`:

* tetrahedron: :math:`\hat N = (1 - X_0 - X_1 - X_2,\ X_0,\ X_1,\ X_2)`;
* hexahedron: :math:`\hat N_a = \prod_k (X_k \text{ if bit } k \text{ of } a \text{ else } 1 - X_k)`.
"""

from __future__ import annotations

import functools

import numpy as np

from fempm.kernels.choice import INLINE
from fempm.kernels.shape import AVAILABLE

__all__ = ["g2p_kernel", "scatter_kernel"]

if AVAILABLE:
    from numba import njit

    from fempm.kernels.affine import APIC, flagged
    from fempm.kernels.kinematics import add_totals
    from fempm.kernels.particle_checks import LINEAR_ELASTIC, NEO_HOOKEAN, count_j, stable_time
    from fempm.kernels.patch import add_node, nodal_ratio
    from fempm.kernels.shape import inside_after_pull_back, star_search
    from fempm.kernels.solid_affine import add_affine3, carried3, jacobian3, offset3, spin3

    @njit(inline=INLINE)
    def inverse_jacobian(K, c):  # pragma: no cover - compiled
        """The 9 entries of ``K[c]``, row by row."""
        return (K[c, 0, 0], K[c, 0, 1], K[c, 0, 2], K[c, 1, 0], K[c, 1, 1], K[c, 1, 2],
                K[c, 2, 0], K[c, 2, 1], K[c, 2, 2])

    @njit(inline=INLINE)
    def node(a, X0, X1, X2, k, hexa):  # pragma: no cover - compiled
        r"""(:math:`N_a`, :math:`\nabla N_a`) at the reference point (X0, X1, X2), ``k`` the 9
        entries of the inverse Jacobian."""
        if hexa:
            f0 = X0 if a & 1 else 1.0 - X0
            f1 = X1 if a & 2 else 1.0 - X1
            f2 = X2 if a & 4 else 1.0 - X2
            d0 = (1.0 if a & 1 else -1.0) * f1 * f2
            d1 = f0 * (1.0 if a & 2 else -1.0) * f2
            d2 = f0 * f1 * (1.0 if a & 4 else -1.0)
            N = f0 * f1 * f2
        elif a == 0:
            N, d0, d1, d2 = 1.0 - X0 - X1 - X2, -1.0, -1.0, -1.0
        else:
            N = X0 if a == 1 else (X1 if a == 2 else X2)
            d0, d1, d2 = 1.0 if a == 1 else 0.0, 1.0 if a == 2 else 0.0, 1.0 if a == 3 else 0.0
        return (N, d0 * k[0] + d1 * k[3] + d2 * k[6], d0 * k[1] + d1 * k[4] + d2 * k[7],
                d0 * k[2] + d1 * k[5] + d2 * k[8])

    @njit(inline=INLINE)
    def value(a, X0, X1, X2, hexa):  # pragma: no cover - compiled
        r""":math:`N_a` alone at the reference point (X0, X1, X2)."""
        if hexa:
            return (X0 if a & 1 else 1.0 - X0) * (X1 if a & 2 else 1.0 - X1) * (X2 if a & 4 else 1.0 - X2)
        return 1.0 - X0 - X1 - X2 if a == 0 else (X0 if a == 1 else (X1 if a == 2 else X2))

    @njit(inline=INLINE)
    def gradient_of(c, o, X, k, cell_dofs, v, NK, hexa, out):  # pragma: no cover - compiled
        r"""``out`` = :math:`\sum_a v_a \otimes \nabla N_a` of the nodal velocity ``v`` (3, 3)."""
        for j in range(3):
            for e in range(3):
                out[j, e] = 0.0
        for a in range(NK):
            _, gx, gy, gz = node(a, X[0], X[1], X[2], k, hexa)
            i = cell_dofs[c, a]
            for j in range(3):
                vj = v[i, o + j]
                out[j, 0] += vj * gx
                out[j, 1] += vj * gy
                out[j, 2] += vj * gz

    @njit(inline=INLINE)
    def gather(c, o, X, k, cell_dofs, v_new, v_old, blend, kinematics, NK, hexa, spin):  # pragma: no cover
        r"""(:math:`\sum_a N_a v_a^+` (3), with ``blend`` :math:`\sum_a N_a (v_a^+ - v_a)` (3),
        with ``kinematics`` :math:`L = \sum_a v_a^+ \otimes \nabla N_a` (9, row by row), with
        ``spin`` = (APIC, the Jacobian's 9 entries) APIC's spin :math:`\sum_a N_a r_a \times v_a^+`
        (3)), over the dofs of cell ``c`` (columns from ``o``), at reference coordinates ``X`` =
        (X0, X1, X2)."""
        X0, X1, X2 = X
        with_spin, jac = spin
        vg0 = vg1 = vg2 = dv0 = dv1 = dv2 = 0.0
        L00 = L01 = L02 = L10 = L11 = L12 = L20 = L21 = L22 = 0.0
        u00 = u01 = u02 = u10 = u11 = u12 = u20 = u21 = u22 = 0.0
        for a in range(NK):
            N, gx, gy, gz = node(a, X0, X1, X2, k, hexa)
            i = cell_dofs[c, a]
            a0, a1, a2 = v_new[i, o], v_new[i, o + 1], v_new[i, o + 2]
            vg0 += N * a0
            vg1 += N * a1
            vg2 += N * a2
            if with_spin:  # u_q = sum_a N_a X_aq v_a (X_a the reference vertex)
                if a & 1 if hexa else a == 1:
                    u00, u01, u02 = u00 + N * a0, u01 + N * a1, u02 + N * a2
                if a & 2 if hexa else a == 2:
                    u10, u11, u12 = u10 + N * a0, u11 + N * a1, u12 + N * a2
                if a & 4 if hexa else a == 3:
                    u20, u21, u22 = u20 + N * a0, u21 + N * a1, u22 + N * a2
            if blend:
                dv0 += N * (a0 - v_old[i, o])
                dv1 += N * (a1 - v_old[i, o + 1])
                dv2 += N * (a2 - v_old[i, o + 2])
            if kinematics:
                L00, L01, L02 = L00 + a0 * gx, L01 + a0 * gy, L02 + a0 * gz
                L10, L11, L12 = L10 + a1 * gx, L11 + a1 * gy, L12 + a1 * gz
                L20, L21, L22 = L20 + a2 * gx, L21 + a2 * gy, L22 + a2 * gz
        w = spin3(jac, X, (u00, u01, u02, u10, u11, u12, u20, u21, u22), (vg0, vg1, vg2)) if with_spin else (0.0, 0.0, 0.0)
        return vg0, vg1, vg2, dv0, dv1, dv2, (L00, L01, L02, L10, L11, L12, L20, L21, L22), w

    @njit(inline=INLINE)
    def g2p_affine3(p, at, velocities, particle, state, sizes, La):  # pragma: no cover - compiled
        r"""G2P's affine state of particle p (``at`` = (X, k, the Jacobian, cell_dofs, c, o),
        ``particle`` = (its :math:`L_p` of ``v_new``, 9 entries, given with ``kinematics``; APIC's
        spin of ``v_new``)): :math:`C_p = L_p`, or where one of its dofs is flagged below
        ``affine_cutoff`` (``velocities`` = (v_new, the cutoff's velocity, the flags)) the gradient
        of the cutoff's velocity; with ``remap`` (``sizes`` = (NK, hexa, KIND, kinematics,
        remap)) the momenta with their affine part into ``mom`` (``state`` = (C, spin, mom, mass,
        v); :mod:`fempm.kernels.solid_affine`)."""
        X, k, jac, cell_dofs, c, o = at
        v_new, va, weak = velocities
        Lp, sp = particle
        C, spin, mom, mass, v = state
        NK, hexa, KIND, kinematics, remap = sizes
        apart = va.shape[0] > 0 and flagged(weak, cell_dofs, c, NK)
        if apart or not kinematics:
            gradient_of(c, o, X, k, cell_dofs, va if apart else v_new, NK, hexa, La)
            for e in range(9):
                C[p, e // 3, e % 3] = La[e // 3, e % 3]
        else:
            for e in range(9):
                C[p, e // 3, e % 3] = Lp[e]
        if KIND == APIC:
            spin[p, 0], spin[p, 1], spin[p, 2] = sp
        if remap:
            mp = mass[p]
            cc = carried3(C, spin, p, X, jac, hexa, KIND)
            mc = (mp * cc[0], mp * cc[1], mp * cc[2], mp * cc[3], mp * cc[4], mp * cc[5], mp * cc[6], mp * cc[7],
                  mp * cc[8])
            for a in range(NK):
                add_affine3(mom, cell_dofs[c, a], o, node(a, X[0], X[1], X[2], k, hexa)[0],
                            (mp * v[p, 0], mp * v[p, 1], mp * v[p, 2]), mc, offset3(a, X[0], X[1], X[2], jac, hexa))

    @njit(inline=INLINE)
    def deform(F, p, dt, L):  # pragma: no cover - compiled
        r""":math:`F_p \leftarrow (I + \Delta t L) F_p` (``L`` 9 entries, row by row); returns
        the new entries (9, row by row) and :math:`\det F_p`, in scalars (not read back)."""
        f00, f01, f02 = F[p, 0, 0], F[p, 0, 1], F[p, 0, 2]
        f10, f11, f12 = F[p, 1, 0], F[p, 1, 1], F[p, 1, 2]
        f20, f21, f22 = F[p, 2, 0], F[p, 2, 1], F[p, 2, 2]
        a0, a1, a2 = dt * L[0], dt * L[1], dt * L[2]
        n00, n01, n02 = f00 + a0 * f00 + a1 * f10 + a2 * f20, f01 + a0 * f01 + a1 * f11 + a2 * f21, \
            f02 + a0 * f02 + a1 * f12 + a2 * f22
        a0, a1, a2 = dt * L[3], dt * L[4], dt * L[5]
        n10, n11, n12 = f10 + a0 * f00 + a1 * f10 + a2 * f20, f11 + a0 * f01 + a1 * f11 + a2 * f21, \
            f12 + a0 * f02 + a1 * f12 + a2 * f22
        a0, a1, a2 = dt * L[6], dt * L[7], dt * L[8]
        n20, n21, n22 = f20 + a0 * f00 + a1 * f10 + a2 * f20, f21 + a0 * f01 + a1 * f11 + a2 * f21, \
            f22 + a0 * f02 + a1 * f12 + a2 * f22
        F[p, 0, 0], F[p, 0, 1], F[p, 0, 2] = n00, n01, n02
        F[p, 1, 0], F[p, 1, 1], F[p, 1, 2] = n10, n11, n12
        F[p, 2, 0], F[p, 2, 1], F[p, 2, 2] = n20, n21, n22
        J = n00 * (n11 * n22 - n12 * n21) - n01 * (n10 * n22 - n12 * n20) + n02 * (n10 * n21 - n11 * n20)
        return (n00, n01, n02, n10, n11, n12, n20, n21, n22), J

    @njit(inline=INLINE)
    def law_stress(sigma, p, code, lam, mu, n, J):  # pragma: no cover - compiled
        r"""``sigma[p]`` of the compiled law ``code`` (else left as it is) for :math:`F` of the
        9 entries ``n`` (row by row), :math:`J = \det F > 0`: the laws of
        :func:`fempm.kernels.kinematics.neo_hookean_at` and
        :func:`~fempm.kernels.kinematics.linear_elastic_at` in scalars."""
        if code == NEO_HOOKEAN:
            inv = 1.0 / J
            vol = lam * np.log(J)
            for i in range(3):
                for j in range(i, 3):
                    b = n[3 * i] * n[3 * j] + n[3 * i + 1] * n[3 * j + 1] + n[3 * i + 2] * n[3 * j + 2]
                    if i == j:
                        sigma[p, i, i] = (mu * (b - 1.0) + vol) * inv
                    else:
                        sigma[p, i, j] = sigma[p, j, i] = mu * b * inv
        elif code == LINEAR_ELASTIC:
            tr = (n[0] - 1.0) + (n[4] - 1.0) + (n[8] - 1.0)
            for i in range(3):
                for j in range(i, 3):
                    if i == j:
                        sigma[p, i, i] = lam * tr + 2.0 * mu * (n[4 * i] - 1.0)
                    else:
                        sigma[p, i, j] = sigma[p, j, i] = 2.0 * mu * (0.5 * (n[3 * i + j] + n[3 * j + i]))

    @njit(inline=INLINE)
    def add_pressure(average, p, at, state, NK, hexa):  # pragma: no cover - compiled
        r"""F-bar's pressure sums of the next force pass (:func:`fempm.kernels.fbar.pressure_kernel`)
        for particle p where it ends the pass: :math:`N_a V_p` and :math:`N_a V_p\,\mathrm{tr}\,
        \sigma_p / 3` into ``average.sums`` (dofs, 2 B), their blocks marked in ``average.dirty``;
        ``at`` = (its cell, the reference coordinates X, cell_dofs), ``state`` = (volume, sigma, body)."""
        c, X, cell_dofs = at
        volume, sigma, body = state
        out, dirty, bodies = average.sums, average.dirty, average.bodies
        b = body[p]
        w = volume[p]
        f = (sigma[p, 0, 0] + sigma[p, 1, 1] + sigma[p, 2, 2]) * (1.0 / 3.0)
        X0, X1, X2 = X[p, 0], X[p, 1], X[p, 2]
        for a in range(NK):
            add_node(out, dirty, cell_dofs[c, a], b, bodies, value(a, X0, X1, X2, hexa) * w, f)

    @njit(inline=INLINE)
    def move_to(x, p, v, vg0, vg1, vg2, own, dt):  # pragma: no cover - compiled
        """``x[p]`` += dt times the grid velocity (or, ``own``, the particle's); whether x and v
        are finite."""
        x[p, 0] += dt * (v[p, 0] if own else vg0)
        x[p, 1] += dt * (v[p, 1] if own else vg1)
        x[p, 2] += dt * (v[p, 2] if own else vg2)
        speed2 = v[p, 0] * v[p, 0] + v[p, 1] * v[p, 1] + v[p, 2] * v[p, 2]
        return np.isfinite(x[p, 0]) and np.isfinite(x[p, 1]) and np.isfinite(x[p, 2]) and np.isfinite(speed2)


@functools.cache
def scatter_kernel(hexa: bool, with_mass: bool, with_momentum: bool, with_force: bool, with_dt: bool, has_fext: bool,
                   bound: bool, grouped: bool = False, with_gradient: bool = False, kind: int = 0,
                   averaged: bool = False):
    """:func:`fempm.kernels.lumped._scatter_kernel` for ``tetrahedron`` or (``hexa``) affine
    ``hexahedron`` cells (``kind``, APIC or TPIC: the momenta with the particles' affine part,
    :mod:`fempm.kernels.solid_affine`; ``averaged``: F-bar's averaged pressure in the force)."""
    NK = 8 if hexa else 4
    CV = 1 if with_mass else 0
    CF = CV + (3 if with_momentum else 0)
    CG = CF + (3 if with_force else 0)
    KIND = kind

    @njit(cache=True, error_model="numpy")
    def scatter(where, state, laws, forces, out, stable, groups, carried=None):  # pragma: no cover
        cells, X, K, cell_dofs = where
        mass, v, volume, sigma, body = state.mass, state.v, state.volume, state.sigma, state.body
        modulus, g, fext, h, c = laws.modulus, forces.g, forces.fext, stable.h, stable.c
        group, stride, patch = groups.group, groups.stride, forces.patch
        bodies = patch.shape[1] // 2
        C, spin = (carried.C, carried.spin) if KIND else (np.empty((0, 3, 3)), np.empty((0, 1)))
        mc = jac = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        best = 0.0 if bound else np.inf
        fe0 = fe1 = fe2 = s00 = s01 = s02 = s10 = s11 = s12 = s20 = s21 = s22 = 0.0
        for p in range(len(cells)):
            cp = cells[p]
            X0, X1, X2 = X[p, 0], X[p, 1], X[p, 2]
            k = inverse_jacobian(K, cp)
            m, V = mass[p], volume[p]
            mv0, mv1, mv2 = m * v[p, 0], m * v[p, 1], m * v[p, 2]
            if with_dt:
                speed = v[p, 0] * v[p, 0] + v[p, 1] * v[p, 1] + v[p, 2] * v[p, 2]
                best = stable_time(best, bound, m, V, speed, modulus[body[p]], c, p, h[cp])
            if with_force:
                fe0, fe1, fe2 = m * g[0], m * g[1], m * g[2]
                if has_fext:
                    fe0, fe1, fe2 = fe0 + fext[p, 0], fe1 + fext[p, 1], fe2 + fext[p, 2]
                s00, s01, s02 = sigma[p, 0, 0], sigma[p, 0, 1], sigma[p, 0, 2]
                s10, s11, s12 = sigma[p, 1, 0], sigma[p, 1, 1], sigma[p, 1, 2]
                s20, s21, s22 = sigma[p, 2, 0], sigma[p, 2, 1], sigma[p, 2, 2]
                if averaged:  # F-bar: the patch-averaged pressure
                    t = 0.0
                    for a in range(NK):
                        t += node(a, X0, X1, X2, k, hexa)[0] * nodal_ratio(patch, cell_dofs[cp, a], body[p], bodies)
                    t -= (s00 + s11 + s22) / 3.0
                    s00, s11, s22 = s00 + t, s11 + t, s22 + t
            o = group[p] * stride if grouped else 0
            if with_momentum and KIND:  # the matrix the momenta carry (times the mass)
                jac = jacobian3(K, cp)
                cc = carried3(C, spin, p, (X0, X1, X2), jac, hexa, KIND)
                mc = (m * cc[0], m * cc[1], m * cc[2], m * cc[3], m * cc[4], m * cc[5], m * cc[6], m * cc[7], m * cc[8])
            for a in range(NK):
                N, gx, gy, gz = node(a, X0, X1, X2, k, hexa)
                i = cell_dofs[cp, a]
                if with_mass:
                    out[i, o] += N * m
                if with_momentum and KIND:
                    add_affine3(out, i, o + CV, N, (mv0, mv1, mv2), mc, offset3(a, X0, X1, X2, jac, hexa))
                elif with_momentum:
                    out[i, o + CV] += N * mv0
                    out[i, o + CV + 1] += N * mv1
                    out[i, o + CV + 2] += N * mv2
                if with_force:
                    out[i, o + CF] += N * fe0 - V * (s00 * gx + s01 * gy + s02 * gz)
                    out[i, o + CF + 1] += N * fe1 - V * (s10 * gx + s11 * gy + s12 * gz)
                    out[i, o + CF + 2] += N * fe2 - V * (s20 * gx + s21 * gy + s22 * gz)
                if with_gradient:
                    out[i, o + CG] += m * gx
                    out[i, o + CG + 1] += m * gy
                    out[i, o + CG + 2] += m * gz
        return 1.0 / np.sqrt(2.0 * best) if bound else best

    return scatter


@functools.cache
def g2p_kernel(hexa: bool, blend: bool, kinematics: bool, move: bool, remap: bool, totals: bool = False,
               grouped: bool = False, kind: int = 0, remap_affine: bool = False, pressures: bool = False):
    """:func:`fempm.kernels.lumped._g2p_kernel` for ``tetrahedron`` or (``hexa``) affine
    ``hexahedron`` cells (``kind``, APIC or TPIC, in a blend pass: the affine state and with
    ``remap_affine`` the re-map with it, :mod:`fempm.kernels.solid_affine`); with ``pressures``
    (a moving pass, the argument ``average``: an :class:`~fempm.kernels.bundles.Averaged`)
    F-bar's pressure sums of the next force pass where each particle ends (:func:`add_pressure`)."""
    NK = 8 if hexa else 4
    KIND = kind

    @njit(cache=True, error_model="numpy")
    def g2p_update(where, grid, state, laws, moves, outputs, groups, carried=None, average=None):  # pragma: no cover
        cells, X, K, cell_dofs = where
        v_new, v_old, flip, dt, by_particle = grid
        x, v, F, volume0, volume, sigma, body, mass = state
        law, lam, mu = laws.law, laws.lam, laws.mu
        x0, tol, left, star = moves
        L, mom, sums = outputs
        group, rigid = groups.group, groups.rigid
        n, keep_L = len(cells), L.shape[0] == len(cells)
        nonfinite_j, inverted, jmin, jmax, nonfinite = 0, 0, np.inf, -np.inf, 0  # the pass's checks
        acc = np.zeros(6)  # the state's sums (totals)
        if KIND:
            C, spin, _, va, weak = carried
        else:  # (typed, unused)
            C, spin, va, weak = np.empty((0, 3, 3)), np.empty((0, 1)), np.empty((0, 3)), np.empty(0, np.uint8)
        La, jac = np.empty((3, 3)), (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        for p in range(n):
            c = cells[p]
            X0, X1, X2 = X[p, 0], X[p, 1], X[p, 2]
            k = inverse_jacobian(K, c)
            o = group[p] * 3 if grouped else 0
            still = grouped and rigid[group[p]]  # a rigid body's particle: its own velocity, L = 0
            if KIND:
                jac = jacobian3(K, c)
            vg0, vg1, vg2, dv0, dv1, dv2, Lp, sp = gather(c, o, (X0, X1, X2), k, cell_dofs, v_new, v_old, blend,
                                                          kinematics and not still, NK, hexa, (KIND == APIC, jac))
            if blend and not still:
                v[p, 0] = flip * (v[p, 0] + dv0) + (1.0 - flip) * vg0
                v[p, 1] = flip * (v[p, 1] + dv1) + (1.0 - flip) * vg1
                v[p, 2] = flip * (v[p, 2] + dv2) + (1.0 - flip) * vg2
            if KIND:  # the affine state: C = L of v_new (or of the cutoff's velocity), APIC's spin of v_new
                g2p_affine3(p, ((X0, X1, X2), k, jac, cell_dofs, c, o), (v_new, va, weak), (Lp, sp), (C, spin, mom, mass, v),
                            (NK, hexa, KIND, kinematics, remap and remap_affine), La)
            if remap and not (KIND and remap_affine):  # MUSL: the blended momenta back to the grid, in the same pass
                for a in range(NK):
                    i = cell_dofs[c, a]
                    N = node(a, X0, X1, X2, k, hexa)[0]
                    for j in range(3):
                        mom[i, o + j] += N * (mass[p] * v[p, j])
            if kinematics:
                nF, J = deform(F, p, dt, Lp)
                if keep_L:
                    for i in range(9):
                        L[p, i // 3, i % 3] = Lp[i]
                volume[p] = J * volume0[p]
                b = body[p]
                ok, nonfinite_j, inverted, jmin, jmax = count_j(J, nonfinite_j, inverted, jmin, jmax)
                if ok:
                    law_stress(sigma, p, law[b], lam[b], mu[b], nF, J)
            if move:
                if not move_to(x, p, v, vg0, vg1, vg2, by_particle or still, dt):
                    nonfinite += 1  # x or v (v.v: the kinetic energy); the compiled laws' stress is finite where J is
                out = not inside_after_pull_back(x, p, x0, K, c, not hexa, 3, tol, X, True)
                if out:  # the neighbours, while their geometry is in cache
                    e = star_search(x, p, x0, K, c, star, not hexa, 3, tol, X, True)
                    out = e < 0
                    cells[p] = c if out else e
                left[p] = out
                if pressures and not out:
                    add_pressure(average, p, (cells[p], X, cell_dofs), (volume, sigma, body), NK, hexa)
            if totals:
                add_totals(acc, p, mass, v, F, volume0, law[body[p]], lam[body[p]], mu[body[p]], 3)
        if totals:
            sums[:] = acc
        return nonfinite_j, inverted, jmin, jmax, nonfinite

    return g2p_update
