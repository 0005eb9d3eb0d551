r"""The particle passes of particle domains given by sample points, on degree-1 cells (affine or
multilinear: the kernel cell types of :data:`fempm.kernels.shape.CELLS`)
(:class:`fempm.stepping.domain_grid.DomainGrid` drives them; the numpy
:class:`~fempm.transfer.basis.ParticleBasis` with a domain is their reference).

A particle :math:`p` has :math:`Q` samples :math:`y_{pq}` in cells :math:`c_{pq}` with
reference coordinates :math:`Y_{pq}`, value weights :math:`w_{pq}` and gradient weights
:math:`g_{pq}` (:mod:`fempm.transfer.domains`); the averaged basis is

.. math::
    \langle N_i \rangle_p = \sum_q w_{pq} N_i(y_{pq}), \qquad
    \langle \nabla N_i \rangle_p = \sum_q \big(g_{pq} N_i(y_{pq})\big)
    \ \text{(CPDI)} \quad\text{or}\quad \sum_q w_{pq} \nabla N_i(y_{pq}) \ \text{(Gauss GIMP)},

evaluated in the passes (:func:`fempm.kernels.shape.shape`), never stored; a node that several
samples reach gets each share (the sums are the same as over distinct nodes).

* :func:`cpdi1_samples`: the corners :math:`y_{pq} = x_p + R_p s_q`, :math:`R_p = F_p
  \operatorname{diag}(\ell_p)`, :math:`w = 2^{-d}`, :math:`g_{pq} = 2^{-d} R_p^{-T} s_q`.
* :func:`fempm.kernels.sample_location.locate_samples`: each sample's cell, the particle's own
  or one of its vertex star (:func:`fempm.kernels.shape.star_search`), -1 where neither holds it.
* :func:`kernels_for`: ``scatter`` and ``g2p_update``, the passes of
  :mod:`fempm.kernels.lumped` (same arguments, plus the samples) summing over the samples
  instead of the particle's cell, and ``mass_apply``, FMPM's :math:`M_C y` of
  :mod:`fempm.kernels.fmpm` with the averaged basis.
"""

from __future__ import annotations

import functools
from types import SimpleNamespace

import numpy as np

from fempm.kernels import planar_samples
from fempm.kernels.bundles import Basis, Corners, Forces, GridStep, Laws, Moves, Outputs, Samples, Stable, State
from fempm.kernels.choice import INLINE
from fempm.kernels.shape import AVAILABLE, CELLS, MULTILINEAR, is_affine

__all__ = ["kernels_for"]

if AVAILABLE:
    from numba import njit

    from fempm.kernels.cpdi1 import corner_frame, corner_gradient
    from fempm.kernels.kinematics import add_totals
    from fempm.kernels.kinematics import deform_at, law_at
    from fempm.kernels.particle_checks import count_j, stable_time
    from fempm.kernels.shape import inside_after_pull_back, shape, shape_values, star_search


@functools.cache
def kernels_for(cell: str, grad_from_values: bool, planar: bool = True) -> SimpleNamespace:
    """The sample passes ``scatter`` and ``g2p_update`` of one cell type; with
    ``grad_from_values`` the gradient of the average is :math:`\\sum_q w_{pq} \\nabla N_i(y_{pq})`
    (Gauss GIMP), else :math:`\\sum_q g_{pq} N_i(y_{pq})` (CPDI). Where ``tracks`` (the
    scalar 2D passes of :mod:`fempm.kernels.planar_samples`), ``g2p_update(..., corners=(yc,
    moved, bad, sample_cells))`` moves and locates CPDI2's corners in the moving pass
    (:func:`~fempm.kernels.planar_samples.g2p_kernel`)."""

    scatter_kernel, g2p_kernel = _scatter_kernel, _g2p_kernel
    tracks = cell in ("triangle", "quadrilateral", "quadrilateral" + MULTILINEAR) and planar
    if tracks:
        scatter_kernel = functools.partial(_planar, planar_samples.scatter_kernel)
        g2p_kernel = functools.partial(_planar, planar_samples.g2p_kernel)

    def scatter(where: Basis, samples: Samples, state: State, laws: Laws, forces: Forces, out, cm: int, cv: int,
                cf: int, stable: Stable, bound: bool = False) -> float:
        kernel = scatter_kernel(cell, grad_from_values, samples.Fw.shape[0] > 0, cm >= 0, cv >= 0, cf >= 0,
                                stable.h.shape[0] > 0, forces.fext.shape[0] > 0, bool(bound))
        return kernel(where, samples, state, laws, forces, out, stable)

    def g2p_update(where: Basis, samples: Samples, grid: GridStep, state: State, laws: Laws, moves: Moves,
                   outputs: Outputs, *, blend: bool, kinematics: bool, move: bool, corners: Corners | None = None):
        remap = blend and outputs.mom.shape[0] > 0
        totals = move and outputs.sums.shape[0] > 0
        flags = (cell, grad_from_values, samples.Fw.shape[0] > 0, bool(blend), bool(kinematics), bool(move), remap,
                 totals)
        args = (where, samples, grid, state, laws, moves, outputs)
        if not tracks:
            return g2p_kernel(*flags)(*args)
        return g2p_kernel(*flags, corners is not None)(*args, corners if corners is not None else NOT_TRACKED)

    def mass_apply(where: Basis, samples: Samples, mass, y, lump, out) -> None:
        """:func:`fempm.kernels.fmpm.mass_apply` with the averaged basis,
        :math:`(M_C y)_i = \\sum_p M_p \\langle N_i \\rangle_p \\sum_j \\langle N_j \\rangle_p y_j`."""
        kernel = (planar_samples.mass_apply_kernel(cell == "triangle", grad_from_values, samples.Fw.shape[0] > 0)
                  if tracks and y.shape[1] % 2 == 0 else _mass_apply_kernel(cell, grad_from_values,
                                                                            samples.Fw.shape[0] > 0))
        kernel(where, samples, mass, y, lump, out)

    return SimpleNamespace(scatter=scatter, g2p_update=g2p_update, mass_apply=mass_apply, tracks=tracks)


#: the corner arrays of a G2P pass that does not move CPDI2 corners (:func:`kernels_for`)
NOT_TRACKED = Corners(np.zeros((0, 0, 2)), np.zeros((0, 0, 2)), np.zeros(2, dtype=np.int64), 0)


def _planar(make, cell: str, *flags):
    """A kernel of :mod:`fempm.kernels.planar_samples` in the place of a generic one of ``cell``."""
    return make(cell == "triangle", is_affine(cell), *flags)


if AVAILABLE:
    @njit(inline=INLINE)
    def particle_basis(p, samples, simplex, affine, D, NK, grad_from_values, corners, scratch):  # pragma: no cover
        r"""The averaged basis of particle ``p`` by cell: the distinct cells its samples lie in
        (``cells``, returned their number) and in row ``k`` the weighted values ``W[k]`` (NK,)
        and gradients ``GW[k]`` (NK, D) of the samples in ``cells[k]`` summed (samples sharing a
        cell share its nodes: one scatter or gather per cell instead of per sample). With
        ``corners`` the weights are CPDI1's of ``Fw[p]`` and ``lp[p]`` (:mod:`fempm.kernels.cpdi1`).
        ``samples``: :class:`~fempm.kernels.bundles.Samples`; ``scratch``: (N, G, cells, W, GW,
        R, Ri), the arrays it writes."""
        sc, Y, w, gw, Fw, lp, signs, K, _ = samples
        N, G, cells, W, GW, R, Ri = scratch
        Q = sc.shape[1]
        share = 1.0 / Q
        if corners:
            corner_frame(Fw, lp, p, D, R, Ri)
        ncell = 0
        for q in range(Q):
            wq = share if corners else w[p, q]
            if grad_from_values and wq == 0.0:
                continue  # a sample of no weight (GIMP's cut or unused samples)
            c = sc[p, q]
            k = 0
            while k < ncell and cells[k] != c:
                k += 1
            if k == ncell:
                cells[k] = c
                ncell += 1
                for a in range(NK):
                    W[k, a] = 0.0
                    for e in range(D):
                        GW[k, a, e] = 0.0
            if grad_from_values:
                shape(Y, p * Q + q, K, c, simplex, affine, D, NK, N, G)
            else:  # CPDI: the gradient weights times the values
                shape_values(Y, p * Q + q, simplex, D, NK, N)
            if not grad_from_values:  # CPDI: the sample's gradient weight into row 0 of G
                for e in range(D):
                    G[0, e] = share * corner_gradient(Ri, signs, q, e, D) if corners else gw[p, q, e]
            for a in range(NK):
                W[k, a] += wq * N[a]
                for e in range(D):
                    GW[k, a, e] += wq * G[a, e] if grad_from_values else G[0, e] * N[a]
        return ncell


@functools.cache
def _scatter_kernel(cell: str, grad_from_values: bool, corners: bool, with_mass: bool, with_momentum: bool,
                    with_force: bool, with_dt: bool, has_fext: bool, bound: bool):
    """:func:`fempm.kernels.lumped._scatter_kernel` over the samples."""
    D, NK, SIMPLEX = CELLS[cell]
    AFFINE = is_affine(cell)
    CV = 1 if with_mass else 0
    CF = CV + (D if with_momentum else 0)

    @njit(cache=True, error_model="numpy")
    def scatter(where, samples, state, laws, forces, out, stable):  # pragma: no cover
        cells = where.cells
        sc, cell_dofs = samples.sc, samples.cell_dofs
        mass, v, volume, sigma, body = state.mass, state.v, state.volume, state.sigma, state.body
        modulus, g, fext, h, c = laws.modulus, forces.g, forces.fext, stable.h, stable.c
        Q = sc.shape[1]
        N, G, cs = np.empty(NK), np.empty((NK, D)), np.empty(Q, np.int32)
        W, GW, R, Ri = np.empty((Q, NK)), np.empty((Q, NK, D)), np.empty((D, D)), np.empty((D, D))
        mv, fe, sg = np.empty(D), np.empty(D), np.empty((D, D))
        best = 0.0 if bound else np.inf
        for p in range(len(cells)):
            m = mass[p]
            V = volume[p]
            speed = 0.0
            for j in range(D):
                mv[j] = m * v[p, j]
                speed += v[p, j] * v[p, j]
                if with_force:
                    fe[j] = m * g[j] + (fext[p, j] if has_fext else 0.0)
                    for e in range(D):
                        sg[j, e] = sigma[p, j, e]
            if with_dt:
                best = stable_time(best, bound, m, V, speed, modulus[body[p]], c, p, h[cells[p]])
            ncell = particle_basis(p, samples, SIMPLEX, AFFINE, D, NK, grad_from_values, corners,
                                    (N, G, cs, W, GW, R, Ri))
            for k in range(ncell):
                cq = cs[k]
                for a in range(NK):
                    i = cell_dofs[cq, a]
                    wa = W[k, a]
                    if with_mass:
                        out[i, 0] += wa * m
                    if with_momentum:
                        for j in range(D):
                            out[i, CV + j] += wa * mv[j]
                    if with_force:
                        for j in range(D):
                            s = 0.0
                            for e in range(D):
                                s += sg[j, e] * GW[k, a, e]
                            out[i, CF + j] += wa * fe[j] - V * s
        return 1.0 / np.sqrt(2.0 * best) if bound else best

    return scatter


@functools.cache
def _g2p_kernel(cell: str, grad_from_values: bool, corners: bool, blend: bool, kinematics: bool, move: bool,
                remap: bool, totals: bool):
    """:func:`fempm.kernels.lumped._g2p_kernel` over the samples (the particle itself moves and
    is relocated as there)."""
    D, NK, SIMPLEX = CELLS[cell]
    AFFINE = is_affine(cell)

    @njit(cache=True, error_model="numpy")
    def g2p_update(where, samples, grid, state, laws, moves, outputs):  # pragma: no cover
        cells, X, K, cell_dofs, sc = where.cells, where.X, samples.K, samples.cell_dofs, samples.sc
        v_new, v_old, flip, dt, by_particle = grid
        x, v, F, volume0, volume, sigma, body, mass = state
        law, lam, mu, x0, tol, left, star = laws.law, laws.lam, laws.mu, moves.x0, moves.tol, moves.left, moves.star
        L, mom, sums = outputs
        n, Q = len(cells), sc.shape[1]
        N, G, cs = np.empty(NK), np.empty((NK, D)), np.empty(Q, np.int32)
        W, GW, R, Ri = np.empty((Q, NK)), np.empty((Q, NK, D)), np.empty((D, D)), np.empty((D, D))
        vg, dv, Lp, Fn = np.empty(D), np.empty(D), np.empty((D, D)), np.empty((D, D))
        keep_L = L.shape[0] == n
        nonfinite_j, inverted, jmin, jmax, nonfinite, acc = 0, 0, np.inf, -np.inf, 0, np.zeros(3 + D)  # checks, sums
        for p in range(n):
            vg[:] = 0.0
            dv[:] = 0.0
            Lp[:] = 0.0
            ncell = particle_basis(p, samples, SIMPLEX, AFFINE, D, NK, grad_from_values, corners,
                                    (N, G, cs, W, GW, R, Ri))
            for k in range(ncell):
                cq = cs[k]
                for a in range(NK):
                    i = cell_dofs[cq, a]
                    wa = W[k, a]
                    for j in range(D):
                        vij = v_new[i, j]
                        vg[j] += wa * vij
                        if blend:
                            dv[j] += wa * (vij - v_old[i, j])
                        if kinematics:
                            for e in range(D):
                                Lp[j, e] += vij * GW[k, a, e]
            if blend:
                for j in range(D):
                    v[p, j] = flip * (v[p, j] + dv[j]) + (1.0 - flip) * vg[j]
            if remap:  # MUSL: the blended momenta back to the grid
                for k in range(ncell):
                    cq = cs[k]
                    for a in range(NK):
                        i = cell_dofs[cq, a]
                        for j in range(D):
                            mom[i, j] += W[k, a] * (mass[p] * v[p, j])
            if kinematics:
                J = deform_at(F, p, dt, Lp, D, Fn)
                if keep_L:
                    for i in range(D):
                        for j in range(D):
                            L[p, i, j] = Lp[i, j]
                volume[p] = J * volume0[p]
                ok, nonfinite_j, inverted, jmin, jmax = count_j(J, nonfinite_j, inverted, jmin, jmax)
                if ok:
                    law_at(law[body[p]], F, p, D, J, lam[body[p]], mu[body[p]], sigma)
            if move:
                ok = True
                speed2 = 0.0
                for j in range(D):
                    x[p, j] += dt * (v[p, j] if by_particle else vg[j])
                    ok = ok and np.isfinite(x[p, j])
                    speed2 += v[p, j] * v[p, j]
                if not (ok and np.isfinite(speed2)):
                    nonfinite += 1
                c = cells[p]
                out = not inside_after_pull_back(x, p, x0, K, c, SIMPLEX, D, tol, X, AFFINE)
                e = star_search(x, p, x0, K, c, star, SIMPLEX, D, tol, X, AFFINE) if out else c
                cells[p] = e if e >= 0 else c
                out = e < 0
                left[p] = out
            if totals:
                add_totals(acc, p, mass, v, F, volume0, law[body[p]], lam[body[p]], mu[body[p]], D)
        if totals:
            sums[:] = acc
        return nonfinite_j, inverted, jmin, jmax, nonfinite

    return g2p_update


@functools.cache
def _mass_apply_kernel(cell: str, grad_from_values: bool, corners: bool):
    """:func:`fempm.kernels.fmpm.mass_apply` over the samples."""
    D, NK, SIMPLEX = CELLS[cell]
    AFFINE = is_affine(cell)

    @njit(cache=True, error_model="numpy")
    def kernel(where, samples, mass, y, lump, out):  # pragma: no cover - compiled
        cells = where.cells
        sc, cell_dofs = samples.sc, samples.cell_dofs
        Q = sc.shape[1]
        N, G, cs = np.empty(NK), np.empty((NK, D)), np.empty(Q, np.int32)
        W, GW, R, Ri = np.empty((Q, NK)), np.empty((Q, NK, D)), np.empty((D, D)), np.empty((D, D))
        k = y.shape[1]
        u = np.empty(k)
        lumping = lump.shape[0] > 0
        for p in range(len(cells)):
            ncell = particle_basis(p, samples, SIMPLEX, AFFINE, D, NK, grad_from_values, corners,
                                    (N, G, cs, W, GW, R, Ri))
            for j in range(k):
                u[j] = 0.0
            ul = 0.0
            for q in range(ncell):
                for a in range(NK):
                    i = cell_dofs[cs[q], a]
                    if lumping and lump[i]:
                        ul += W[q, a]
                    else:
                        for j in range(k):
                            u[j] += W[q, a] * y[i, j]
            m = mass[p]
            for q in range(ncell):
                for a in range(NK):
                    i = cell_dofs[cs[q], a]
                    wa = m * W[q, a]
                    for j in range(k):
                        out[i, j] += wa * u[j]
                    if lumping:
                        out[i, k] += wa * ul

    return kernel
