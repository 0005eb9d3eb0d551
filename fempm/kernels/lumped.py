r"""The lumped-mass explicit step for point particles on affine degree-1 cells, in four
compiled passes (:class:`fempm.stepping.lumped.PointGrid` drives them; the generic
:meth:`fempm.stepping.ExplicitSolver.step` is their reference). The basis is evaluated on the
fly (:func:`fempm.kernels.shape.shape`), never stored.

:func:`scatter` (P2G, one pass, one nodal array with columns ``[m | m v | f]``):

.. math::
    m_i = \sum_p M_p N_{ip}, \qquad (m v)_i = \sum_p M_p v_p N_{ip}, \qquad
    f_i = \sum_p \big(N_{ip} (M_p g + f^{ext}_p) - V_p \sigma_p \nabla N_{ip}\big).

:func:`fempm.kernels.grid_update.grid_velocity` and :func:`~fempm.kernels.grid_update.grid_advance`
(the grid update, on owned and ghost dofs):
:math:`v_i = (m v)_i / m_i` on free dofs with :math:`m_i > \epsilon_a`, 0 elsewhere;
:math:`a_i = f_i / m_i - c\, v_i` (0 on constrained dofs and where :math:`m_i \le \epsilon_w`),
:math:`v_i^+ = v_i + \Delta t\, a_i`.

:func:`g2p_update` (G2P, kinematics, constitutive update and motion in one pass, each part
switched on by a flag): the FLIP blend
:math:`v_p^+ = \alpha (v_p + \sum_i N_{ip}(v_i^+ - v_i)) + (1-\alpha) \sum_i N_{ip} v_i^+`,
:math:`L_p = \sum_i v_i^+ \otimes \nabla N_{ip}`, :math:`F_p^+ = (I + \Delta t L_p) F_p`,
:math:`V_p = J_p V_p^0`, the stress of the compiled laws (1: neo-Hookean, 2: linear elastic;
0: left to the material's own ``stress``), and :math:`x_p^+ = x_p + \Delta t \bar v_p`.

:func:`scatter` also returns the stable time of the state it reads,
:math:`\min_p h_{c(p)} / (c_p + |v_p|)` with :math:`c_p = \sqrt{M_b / \rho_p}` for bodies with
a P-wave modulus :math:`M_b` (else a given ``c_p``).

The particle passes are compiled once per cell type (:func:`kernels_for`; multilinear cells,
whose ``K`` and ``x0`` are the cells' vertices, are a type of their own:
:mod:`fempm.kernels.shape`): the dimension, the number of vertices, the simplex/tensor-product
basis and the affine/multilinear map are constants of the compiled code, so
its small loops unroll (a kernel with run-time sizes is 2-4x slower), and numba caches each.
"""

from __future__ import annotations

import functools
from types import SimpleNamespace

import numpy as np

from fempm.kernels import planar, solid
from fempm.kernels.bundles import (
    NO_AFFINE,
    NO_GROUPS,
    Affine,
    Basis,
    Forces,
    GridStep,
    Groups,
    Laws,
    Moves,
    Outputs,
    Stable,
    State,
)
from fempm.kernels.choice import INLINE
from fempm.kernels.particle_checks import (
    count_j,
    stable_time,
)
from fempm.kernels.shape import AVAILABLE, CELLS, MULTILINEAR, is_affine, space_of

__all__ = ["NO_GROUPS", "NO_STABLE", "PLANAR", "SOLID", "kernels_for"]

#: the cells whose passes are the scalar ones of :mod:`fempm.kernels.planar` (their G2P pass also
#: takes F-bar's averaged kinematics)
PLANAR = ("triangle", "quadrilateral", "quadrilateral" + MULTILINEAR)

#: the cells whose affine transfers run the scalar passes (:mod:`fempm.kernels.planar` with
#: :mod:`fempm.kernels.planar_affine`, :mod:`fempm.kernels.solid`), not the generic ones
AFFINE_SCALAR = ("triangle", "quadrilateral", "tetrahedron", "hexahedron")
#: the cells of the scalar 3D passes (:mod:`fempm.kernels.solid`; hexahedra affine)
SOLID = ("tetrahedron", "hexahedron")
#: no stable time asked of a P2G pass
NO_STABLE = Stable(np.zeros(0), np.zeros(0))

if AVAILABLE:
    from numba import njit

    from fempm.kernels.affine import add_momentum, affine_work, carried_at, flagged, g2p_affine, offsets
    from fempm.kernels.kinematics import add_totals, deform_at, law_at
    from fempm.kernels.patch import average_pressure
    from fempm.kernels.shape import inside_after_pull_back, shape, star_search

    @njit(inline=INLINE)
    def gather(N, G, cell_dofs, c, o, v_new, v_old, blend, kinematics, D, NK, sums):  # pragma: no cover
        r"""The sums over the dofs of cell ``c`` (columns from ``o``), each loaded once, into
        ``sums`` = (vg, dv, Lp): :math:`\sum_a N_a v_a^+` into ``vg``, with ``blend`` :math:`\sum_a N_a (v_a^+ - v_a)` into ``dv``, with ``kinematics``
        :math:`L_p = \sum_a v_a^+ \otimes \nabla N_a` into ``Lp``."""
        vg, dv, Lp = sums
        for j in range(D):
            vg[j] = 0.0
            dv[j] = 0.0
            for e in range(D):
                Lp[j, e] = 0.0
        for a in range(NK):
            i = cell_dofs[c, a]
            w = N[a]
            for j in range(D):
                vij = v_new[i, o + j]
                vg[j] += w * vij
                if blend:
                    dv[j] += w * (vij - v_old[i, o + j])
                if kinematics:
                    for e in range(D):
                        Lp[j, e] += vij * G[a, e]


@functools.cache
def kernels_for(cell: str) -> SimpleNamespace:
    """The particle passes ``scatter`` and ``g2p_update`` compiled for one cell type (for
    triangles and quadrilaterals the scalar ones of :mod:`fempm.kernels.planar`, for tetrahedra
    and affine hexahedra those of :mod:`fempm.kernels.solid`)."""

    scatter_kernel, g2p_kernel = _scatter_kernel, _g2p_kernel
    if cell in PLANAR:
        simplex, affine = cell == "triangle", is_affine(cell)
        scatter_kernel = functools.partial(_planar, planar.scatter_kernel, simplex, affine)
        g2p_kernel = functools.partial(_planar, planar.g2p_kernel, simplex, affine)
    elif cell in SOLID:
        scatter_kernel = functools.partial(_solid, solid.scatter_kernel, cell == "hexahedron")
        g2p_kernel = functools.partial(_solid, solid.g2p_kernel, cell == "hexahedron")

    def scatter(where: Basis, state: State, laws: Laws, forces: Forces, out, cm: int, cv: int, cf: int,
                stable: Stable = NO_STABLE, *, bound: bool = False, groups: Groups = NO_GROUPS, cg: int = -1,
                affine: Affine = NO_AFFINE, kind: int = 0) -> float:
        """See :func:`_scatter_kernel` (the bundles: :mod:`fempm.kernels.bundles`); the columns
        (negative: skipped) choose the compiled variant; with cell sizes ``stable.h`` the stable
        time (a lower bound of it with ``bound``); with a ``groups.group`` per particle the columns
        of group k start at ``k * groups.stride``; ``cg`` >= 0: also the mass gradients; ``kind``
        (1 APIC, 2 TPIC: :mod:`fempm.kernels.affine`): the momenta with the particles' affine
        part (the generic kernel)."""
        flags = (cm >= 0, cv >= 0, cf >= 0, stable.h.shape[0] > 0, forces.fext.shape[0] > 0, bool(bound),
                 groups.group.shape[0] > 0, cg >= 0)
        averaged = cf >= 0 and forces.patch.shape[0] > 0  # F-bar's averaged pressure in the forces
        if kind and cv >= 0:  # the affine transfers: the planar passes on affine 2D cells, else the generic ones
            make = scatter_kernel if cell in AFFINE_SCALAR else _scatter_kernel
            return make(cell, *flags, kind, averaged=averaged)(where, state, laws, forces, out, stable, groups, affine)
        return scatter_kernel(cell, *flags, averaged=averaged)(where, state, laws, forces, out, stable, groups)

    def g2p_update(where: Basis, grid: GridStep, state: State, laws: Laws, moves: Moves, outputs: Outputs,
                   groups: Groups = NO_GROUPS, *, blend: bool, kinematics: bool, move: bool,
                   affine: Affine = NO_AFFINE, kind: int = 0, remap_affine: bool = True, average=None) -> tuple:
        """See :func:`_g2p_kernel` (the bundles: :mod:`fempm.kernels.bundles`); the flags choose
        the compiled variant (``outputs.mom`` with a row per dof: the blend pass also re-maps the
        momenta, MUSL; ``outputs.sums`` of 3 + d entries: the moving pass also sums the state's
        energies; a ``groups.group`` per particle: each takes its group's field, columns ``k d`` to
        ``(k + 1) d``; the particles of a group k with ``groups.rigid[k]`` keep their velocity and
        F (L = 0) and move with their velocity); ``kind`` (1 APIC, 2 TPIC): the blend stores the
        particles' affine matrices (and APIC's spins) into ``affine`` and, with ``remap_affine``,
        re-maps with them (the lumped mass; the consistent mass re-maps the velocities alone: the
        generic kernel); ``average`` (an :class:`~fempm.kernels.bundles.Averaged`): on the :data:`PLANAR`
        cells, a kinematics pass, F-bar's averaged deformation (:func:`fempm.kernels.planar.g2p_kernel`);
        on the :data:`SOLID` cells, a moving pass without kinematics, the pressure sums of the next
        force pass (:func:`fempm.kernels.solid.g2p_kernel`)."""
        remap = blend and outputs.mom.shape[0] > 0
        totals = move and outputs.sums.shape[0] > 0
        flags = (bool(blend), bool(kinematics), bool(move), remap, totals, groups.group.shape[0] > 0)
        if average is not None:
            on = bool(kind and blend)
            if cell in SOLID and move and not kinematics:  # the pressure sums alone
                return g2p_kernel(cell, *flags, kind if on else 0, remap and remap_affine and on, pressures=True)(
                    where, grid, state, laws, moves, outputs, groups, affine, average)
            if cell not in PLANAR or not kinematics:
                raise ValueError(f"F-bar's averaged kinematics in the G2P pass take a kinematics pass on {PLANAR}, "
                                 f"its pressure sums a moving pass without kinematics on {SOLID}")
            return g2p_kernel(cell, *flags, kind if on else 0, remap and remap_affine and on, averaged=True,
                              pressures=average.sums.shape[0] > 0)(
                where, grid, state, laws, moves, outputs, groups, affine, average)
        if kind and blend:
            make = g2p_kernel if cell in AFFINE_SCALAR else _g2p_kernel
            return make(cell, *flags, kind, remap and remap_affine)(where, grid, state, laws, moves, outputs, groups,
                                                                     affine)
        return g2p_kernel(cell, *flags)(where, grid, state, laws, moves, outputs, groups)

    return SimpleNamespace(scatter=scatter, g2p_update=g2p_update)


def _planar(make, simplex: bool, affine: bool, cell: str, *flags, **options):
    """A kernel of :mod:`fempm.kernels.planar` in the place of a generic one of ``cell``."""
    return make(simplex, affine, *flags, **options)


def _solid(make, hexa: bool, cell: str, *flags, **options):
    """A kernel of :mod:`fempm.kernels.solid` in the place of a generic one of ``cell``."""
    return make(hexa, *flags, **options)


@functools.cache
def _scatter_kernel(cell: str, with_mass: bool, with_momentum: bool, with_force: bool, with_dt: bool, has_fext: bool,
                    bound: bool = False, grouped: bool = False, with_gradient: bool = False, kind: int = 0,
                    averaged: bool = False):
    r"""The P2G pass of :func:`kernels_for` with its terms fixed at compile time: the columns of
    ``out`` are [mass | momentum (d) | force (d)], of the terms present. On a basis with
    negative values (P2 Lagrange) the mass column is :math:`\sum_p M_p |N_{ip}|`, the measure
    of support of :meth:`fempm.transfer.Projector.support_masses` (such a basis takes the
    consistent mass only).

    ``with_dt``: also the stable time of the state, :math:`\min_p h_{c(p)} / (c_p + |v_p|)`;
    with ``bound`` a lower bound of it without square roots per particle (a given step only
    needs to be checked against it), from :math:`(c + |v|)^2 \le 2 (c^2 + |v|^2)`:
    :math:`\big(2 \max_p (c_p^2 + |v_p|^2) / h_{c(p)}^2\big)^{-1/2}`.

    ``grouped`` (multi-field contact, :mod:`fempm.stepping.contact_points`): particle p adds to
    the columns of its group, shifted by ``group[p] * stride``. ``with_gradient``: d more
    columns, the mass gradients :math:`\sum_p M_p \nabla N_{ip}`. ``kind`` (1 APIC, 2 TPIC) adds
    the affine part to the momenta, :math:`M_p N_{ip} C_p (x_i - x_p)` of the carried matrix
    (:func:`fempm.kernels.affine.carried`; the kernel then takes the ``affine`` bundle).
    ``averaged`` (F-bar, :mod:`fempm.stepping.fbar_grid`): the force takes :math:`\sigma_p + (\bar
    p_p - p_p) I`, :math:`\bar p_p` the patch average of the pressures summed in ``forces.patch``
    (:mod:`fempm.kernels.patch`)."""
    D, NK, SIMPLEX = CELLS[cell]
    KIND = kind
    AFFINE = is_affine(cell)
    DEGREE, BERNSTEIN = space_of(cell)
    SIGNED = DEGREE == 2 and not BERNSTEIN  # a basis with negative values: the mass column is its support measure
    FROM_K = DEGREE == 1 and AFFINE  # the dofs' offsets from the cell's inverse Jacobian (fempm.kernels.affine.offsets)
    CV = 1 if with_mass else 0
    CF = CV + (D if with_momentum else 0)
    CG = CF + (D if with_force else 0)

    @njit(cache=True, error_model="numpy")
    def scatter(where, state, laws, forces, out, stable, groups, affine=None):  # pragma: no cover
        """Add the particles' mass, momentum and force to ``out`` (ndofs, ncols). Returns the
        stable time of the particles' state (inf without ``with_dt``)."""
        cells, X, K, cell_dofs = where
        x, mass, v, volume, sigma, body = state.x, state.mass, state.v, state.volume, state.sigma, state.body
        modulus, g, fext, h, c = laws.modulus, forces.g, forces.fext, stable.h, stable.c
        group, stride, patch, bodies = groups.group, groups.stride, forces.patch, forces.patch.shape[1] // 2
        N = np.empty(NK)
        G = np.empty((NK, D))
        mv = np.empty(D)
        fe = np.empty(D)
        sg = np.empty((D, D))
        Dm, _, work, (R, Jw) = affine_work(D, NK)
        Cu = work[0]
        if KIND:
            C, spin, xi = affine.C, affine.spin, affine.xi
        else:  # (typed, unused)
            C, spin, xi = np.empty((0, D, D)), np.empty((0, 1)), np.empty((0, D))
        best = 0.0 if bound else np.inf
        for p in range(len(cells)):
            cp = cells[p]
            shape(X, p, K, cp, SIMPLEX, AFFINE, D, NK, N, G, DEGREE, BERNSTEIN)
            m = mass[p]
            V = volume[p]
            speed = 0.0
            for j in range(D):
                mv[j] = m * v[p, j]
                speed += v[p, j] * v[p, j]
                if with_force:
                    fe[j] = m * g[j]
                    if has_fext:
                        fe[j] += fext[p, j]
                    for e in range(D):
                        sg[j, e] = sigma[p, j, e]
            if with_force and averaged:  # F-bar: the patch-averaged pressure
                average_pressure(sg, D, (N, NK, cell_dofs, cp), patch, body[p], bodies)
            if KIND:
                offsets((X, K, cp, cell_dofs, xi, x), p, (D, NK, SIMPLEX, FROM_K), R, Jw)
                carried_at(N, R, (C, spin), p, (D, NK, KIND), Dm, work)
            if with_dt:
                best = stable_time(best, bound, m, V, speed, modulus[body[p]], c, p, h[cp])
            o = group[p] * stride if grouped else 0
            for a in range(NK):
                i = cell_dofs[cp, a]
                w = N[a]
                if with_mass:
                    out[i, o] += (abs(w) if SIGNED else w) * m
                if with_momentum:
                    for j in range(D):
                        t = mv[j]
                        if KIND:
                            for k in range(D):
                                t += m * Cu[j, k] * R[a, k]
                        out[i, o + CV + j] += w * t
                if with_force:
                    for j in range(D):
                        s = 0.0
                        for e in range(D):
                            s += sg[j, e] * G[a, e]
                        out[i, o + CF + j] += w * fe[j] - V * s
                if with_gradient:
                    for j in range(D):
                        out[i, o + CG + j] += m * G[a, j]
        return 1.0 / np.sqrt(2.0 * best) if bound else best

    return scatter


@functools.cache
def _g2p_kernel(cell: str, blend: bool, kinematics: bool, move: bool, remap: bool, totals: bool = False,
                grouped: bool = False, kind: int = 0, remap_affine: bool = False):
    r"""The G2P pass of :func:`kernels_for` with its parts (flags) fixed at compile time,
    one pass over the particles, in place. ``blend``: ``v`` <- the FLIP/PIC blend of ``v_new``
    against ``v_old``. ``kinematics``: ``F``, ``volume`` and the compiled laws' ``sigma`` from
    :math:`L_p` of ``v_new`` (and :math:`L_p` into ``L`` when it has a row per particle). ``move``:
    ``x`` += dt times the grid velocity (or, ``by_particle``, the particle's), then ``X`` <- the
    reference coordinates in the same cell (origins ``x0``) and, where they lie outside it (beyond
    ``tol``), ``cells`` and ``X`` <- the first cell of the vertex star (``c2v``, ``v_offsets``,
    ``v_cells``, ``num_cells``: :func:`fempm.kernels.shape.star_search`) that contains the particle,
    else ``left`` <- True. ``totals`` (a moving pass): ``sums`` <- the sums over the particles of
    the state the pass leaves, :math:`[\sum_p \tfrac12 M_p |v_p|^2,\ \sum_p V^0_p W(F_p),\ \sum_p
    M_p |v_p|,\ \sum_p M_p v_p]` (W of the compiled laws; 0 for the others). Returns (#non-finite J,
    #J <= 0, min J, max J, #non-finite x or v). ``grouped``: particle p reads (and re-maps into) the columns ``group[p] d`` to
    ``(group[p] + 1) d`` of the nodal arrays. ``kind`` (1 APIC, 2 TPIC; a blend pass): the
    particles' affine matrices (of the bundle's ``v`` under ``affine_cutoff``) and APIC's spins
    of ``v_new`` into the ``affine`` bundle (:func:`fempm.kernels.affine.g2p_affine`); ``remap_affine``: the re-map maps them too (the
    lumped mass)."""
    D, NK, SIMPLEX = CELLS[cell]
    KIND = kind
    AFFINE = is_affine(cell)
    DEGREE, BERNSTEIN = space_of(cell)
    # C_p = L_p: equal on degree-1 affine cells (fempm.transfer.affine.closed_form); P2 Lagrange's D_p is no moment
    CLOSED = (DEGREE == 1 and AFFINE) or (DEGREE == 2 and not BERNSTEIN)
    FROM_K = DEGREE == 1 and AFFINE  # the dofs' offsets from the cell's inverse Jacobian (fempm.kernels.affine.offsets)

    @njit(cache=True, error_model="numpy")
    def g2p_update(where, grid, state, laws, moves, outputs, groups, affine=None):  # pragma: no cover
        cells, X, K, cell_dofs = where
        v_new, v_old, flip, dt, by_particle = grid
        x, v, F, volume0, volume, sigma, body, mass = state
        law, lam, mu = laws.law, laws.lam, laws.mu
        x0, tol, left, star = moves
        L, mom, sums = outputs
        group, rigid = groups.group, groups.rigid
        n, N, G = len(cells), np.empty(NK), np.empty((NK, D))
        vg, dv, Lp, Fn = np.empty(D), np.empty(D), np.empty((D, D)), np.empty((D, D))
        keep_L = L.shape[0] == n
        nonfinite_j, inverted, nonfinite, jmin, jmax = 0, 0, 0, np.inf, -np.inf
        acc = np.zeros(3 + D)  # the state's sums (totals)
        Dm, gwork, cwork, (R, Jw) = affine_work(D, NK)
        C, spin, xi, va, weak = affine if KIND else (np.empty((0, D, D)), np.empty((0, 1)), np.empty((0, D)),
                                                     np.empty((0, D)), np.empty(0, np.uint8))  # (typed, unused)
        cut, vga, dva, La = va.shape[0] > 0, np.empty(D), np.empty(D), np.empty((D, D))  # cut: affine_cutoff
        for p in range(n):
            c = cells[p]
            shape(X, p, K, c, SIMPLEX, AFFINE, D, NK, N, G, DEGREE, BERNSTEIN)
            o = group[p] * D if grouped else 0
            still = grouped and rigid[group[p]]  # a rigid body's particle: its own velocity, L = 0
            gather(N, G, cell_dofs, c, o, v_new, v_old, blend, (kinematics or KIND > 0) and not still, D, NK,
                   (vg, dv, Lp))
            if blend and not still:
                for j in range(D):
                    v[p, j] = flip * (v[p, j] + dv[j]) + (1.0 - flip) * vg[j]
            if KIND and blend:
                offsets((X, K, c, cell_dofs, xi, x), p, (D, NK, SIMPLEX, FROM_K), R, Jw)
                apart = cut and flagged(weak, cell_dofs, c, NK)  # the matrix of the cutoff's velocity, the spin of v_new
                if apart:
                    gather(N, G, cell_dofs, c, o, va, va, False, True, D, NK, (vga, dva, La))
                g2p_affine((N, cell_dofs, c, o), (va if apart else v_new, v_new, apart), R, p, La if apart else Lp,
                           (D, NK, KIND, CLOSED), (C, spin), gwork)
            if remap:  # MUSL: the blended momenta back to the grid, in the same pass
                if remap_affine:
                    carried_at(N, R, (C, spin), p, (D, NK, KIND), Dm, cwork)
                add_momentum((N, cell_dofs, c, o), mom, (v, p, mass[p]), (D, NK), (cwork[0], R, remap_affine))
            if kinematics:
                J = deform_at(F, p, dt, Lp, D, Fn)
                if keep_L:
                    L[p, :, :] = Lp
                volume[p] = J * volume0[p]
                ok, nonfinite_j, inverted, jmin, jmax = count_j(J, nonfinite_j, inverted, jmin, jmax)
                if ok:
                    law_at(law[body[p]], F, p, D, J, lam[body[p]], mu[body[p]], sigma)
            if move:
                ok = True
                speed2 = 0.0
                for j in range(D):  # the stress of the compiled laws is finite where J is
                    x[p, j] += dt * (v[p, j] if by_particle or still else vg[j])
                    ok = ok and np.isfinite(x[p, j])
                    speed2 += v[p, j] * v[p, j]
                if not (ok and np.isfinite(speed2)):  # x or v (v.v: the kinetic energy)
                    nonfinite += 1
                out = not inside_after_pull_back(x, p, x0, K, c, SIMPLEX, D, tol, X, AFFINE)
                if out:  # the neighbours, while their geometry is in cache
                    e = star_search(x, p, x0, K, c, star, SIMPLEX, D, tol, X, AFFINE)
                    if e >= 0:
                        cells[p] = e
                        out = False
                left[p] = out
            if totals:
                add_totals(acc, p, mass, v, F, volume0, law[body[p]], lam[body[p]], mu[body[p]], D)
        if totals:
            sums[:] = acc
        return nonfinite_j, inverted, jmin, jmax, nonfinite

    return g2p_update
