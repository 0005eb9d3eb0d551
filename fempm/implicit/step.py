r"""The implicit step (``StepOptions(integrator="implicit")``): Newton's method on the grid's
displacement increment, then the particles updated as in the explicit step.

A step of :math:`\Delta t` from the particles' state at :math:`t_n`:

1. the basis at the particles, the lumped masses :math:`m_a = \sum_p M_p N_a(x_p)`, the dofs
   that hold: components held by the conditions (fixed, axis-aligned slip) and dofs that no
   particle reaches (:math:`\sum_p M_p N_a(x_p)^2 = 0`: the consistent mass's diagonal, which
   unlike :math:`m_a` sees the vertices of P2 Lagrange simplices); with Newmark's method the
   grid velocity and acceleration of the particles', :math:`v_a = \sum_p M_p N_a v_p / m_a`
   (likewise :math:`a_a`), or with the consistent mass :math:`v = M^{-1} \sum_p M_p N v_p`;
2. Newton's method (:class:`fempm.implicit.newton.Newton`, PETSc SNES, prefix
   ``fempm_implicit_``) on

   .. math::
       R(\Delta u) = M a^{+}(\Delta u) + f^{int}(\Delta u) - f^{ext}(t_n + \Delta t) = 0

   (:mod:`fempm.implicit.operator`, with F-bar :mod:`fempm.implicit.fbar`;
   :mod:`fempm.stepping.dynamics` for :math:`a^{+}`, no
   inertia when quasi-static, the loads then scaled by ``StepOptions.load_ramp``), the held
   components' rows :math:`\Delta u_{ai} = 0`;
3. the particles: :math:`F_p \leftarrow (I + G_p) F_p`, the laws' stress and internal
   variables of the converged increment, :math:`V_p = J_p V^0_p`,
   :math:`x_p \leftarrow x_p + \sum_a N_a \Delta u_a`; with Newmark's method
   :math:`a_p = \sum_a N_a a^{+}_a` and the velocity blended as in the explicit G2P
   (FLIP :math:`v_p + \sum_a N_a (v^{+}_a - v_a)`, PIC :math:`\sum_a N_a v^{+}_a`); quasi-static,
   :math:`v_p = a_p = 0`.

A Newton solve that fails with the configured line search is taken once more with full Newton
steps (PETSc's ``basic`` line search). A step whose Newton iterations still do not converge is
not accepted: it is taken again as two halves
(each of which may be halved again, up to ``StepOptions.max_cuts`` times), and every cut is
counted in :attr:`fempm.stepping.state.StepRecord.cut_steps`.
"""

from __future__ import annotations


import dolfinx.la
import numpy as np
import numpy.typing as npt
from mpi4py import MPI
from petsc4py import PETSc

from fempm import petsc as fpetsc
from fempm.implicit.fbar import FBarIncrementOperator, PatchCoupling
from fempm.implicit.newton import Newton, null_pivots
from fempm.implicit.operator import IncrementOperator
from fempm.implicit.pattern import KeptPattern
from fempm.kernels.implicit import increment_determinants
from fempm.stepping.particle_stages import ParticleStages
from fempm.stepping.state import StepState
from fempm.stepping.loads import external_forces
from fempm.transfer import affine, g2p
from fempm.transfer.basis import is_nonnegative
from fempm.transfer.grid_solves import negative_basis_message
from fempm.transfer.mapping import SUPPORT_TOL
from fempm.transfer.transfers import AFFINE_FIELD, SPIN_FIELD


#: the residual's round-off floor in machine epsilons of |J|_inf max(|du|_inf, |u|_inf) sqrt(N)
#: (:meth:`ImplicitStep._round_off`)
ROUND_OFF = 100.0

__all__ = ["ImplicitStep"]


class ImplicitStep:
    """The implicit step of ``state`` (see the module): it composes the particles' stages of a
    step (:class:`~fempm.stepping.particle_stages.ParticleStages`: the basis, the kinematics and
    the laws, the motion, the checks, the relocation) with its own Newton solve of the grid.

    Raises:
        ValueError: What the implicit step does not take (contact, conditions other than fixed
            dofs and axis-aligned slip; the options it refuses, :class:`~fempm.stepping.StepOptions`).
        TypeError: A law without a tangent, unless ``StepOptions(tangent="finite-difference")``.
    """

    def __init__(self, state: StepState):
        self.state = state
        self.options = opts = state.options
        self.particle_stages = ParticleStages(state)
        if state.contact is not None:
            raise ValueError("the implicit step does not take contact between bodies (contact=...) yet")
        if not state.conditions.zero_components:
            raise ValueError(f"the implicit step takes fixed dofs and slip walls normal to a coordinate axis, not "
                             f"{' or '.join(state.conditions.other_kinds)}: take the explicit step")
        if not opts.finite_difference_tangent:
            for mat in state.materials:
                if not hasattr(mat, "tangent"):
                    raise TypeError(f"{type(mat).__name__} has no tangent(F, G, sigma, state), which the implicit step "
                                    "needs: give the law one, or take StepOptions(tangent='finite-difference') "
                                    "(on the command line --tangent finite-difference)")
        self.integration = opts.integration
        self.consistent = opts.mass_model.matrix
        if self.integration.inertia and not self.consistent and not is_nonnegative(state.V.element.basix_element):
            raise ValueError("Newmark's inertia: " + negative_basis_message(opts.mass_model.label,
                                                                             state.V.element.basix_element.degree))
        self.newton = Newton(state.particles.comm)
        self.pattern = KeptPattern()
        self.last = None  # the NewtonResult of the last accepted (sub)step
        self.last_failure = ""  # what the last failed Newton solve reported

    def step(self, dt: float) -> float:
        """Advance the particles by ``dt`` (in halves where Newton fails, see the module); returns ``dt``.

        Note:
            Collective.
        """
        if dt is None or not dt > 0.0:
            raise ValueError(f"the implicit step needs a time step dt > 0 (got {dt}): it is not bound by the CFL "
                             "condition, so there is no stable step to default to")
        record = self.state.record
        record.load_work, record.load_impulse = 0.0, np.zeros(self.state.particles.gdim)
        if self.integration.inertia:
            record.reaction = np.zeros(self.state.particles.gdim)
        self._advance(self.state.t, dt, 0)
        return dt

    def _advance(self, t: float, dt: float, cuts: int) -> None:
        s = self.state
        if self._try(t, dt):
            return
        if cuts == self.options.max_cuts:
            s.fail(f"the implicit step did not converge ({self.last_failure}) after {cuts} halving(s) of dt, "
                   f"down to dt = {dt:.3g}")
        s.record.cut_steps += 1
        self._advance(t, 0.5 * dt, cuts + 1)
        self._advance(t + 0.5 * dt, 0.5 * dt, cuts + 1)

    def _try(self, t: float, dt: float) -> bool:
        """One Newton solve over [t, t + dt]; the particles updated if it converged."""
        s, p, integ = self.state, self.state.particles, self.integration
        d = p.gdim
        basis = self.particle_stages.open_basis()
        fbar = self.options.volumetric_average is not None
        op = (FBarIncrementOperator if fbar else IncrementOperator)(
            basis, p, s.materials, finite_difference=self.options.finite_difference_tangent, dt=dt)
        m = op.nodal(p.mass[:, None])[:, 0]
        free = self._free(op.support(), basis.num_dofs_local)
        v, a = np.zeros_like(free, dtype=float), np.zeros_like(free, dtype=float)
        if integ.inertia:
            f = p.fields
            f.setdefault("a", np.zeros((len(p), d)))
            va = self._grid_motion(basis, op, free, m)
            v, a = np.where(free, va[:, :d], 0.0), np.where(free, va[:, d:], 0.0)
        fext = self._loads(op, t + dt)
        c = integ.mass_factor(dt)
        imap = basis.index_map
        owned = imap.size_local
        held = np.flatnonzero(~free[:owned].ravel()).astype(np.int32)
        ghosted = dolfinx.la.vector(imap, bs=d)

        def increment(x) -> npt.NDArray:
            ghosted.array[: owned * d] = x.array_r
            ghosted.scatter_forward()
            return ghosted.array.reshape(-1, d).copy()

        def inverts(G) -> bool:
            bad = int(np.count_nonzero(~(increment_determinants(G) > 0.0)))
            return bool(p.comm.allreduce(bad))

        def residual(x, r) -> None:
            du = increment(x)
            G = op.gradients(du)
            law = op.law_gradients(G)  # (G itself without F-bar: its determinants are checked once)
            if inverts(G) or (law is not G and inverts(law)):  # outside the residual's domain: an infinite norm,
                r.set(np.inf)  # which the line search steps back from
                return
            R = op.internal_force(op.forces(G)) - fext
            if integ.inertia:
                R += op.mass_times(integ.acceleration(du, v, a, dt), self.consistent, m)
            R[~free] = du[~free]
            r.array[:] = R[:owned].ravel()

        patches = PatchCoupling(op) if fbar else None
        if patches is None:
            J = local = self.pattern.matrix_for(op, imap, d)  # kept while the particles keep their dofs
        else:
            rows, cols = op.pattern()
            local = fpetsc.coo_pattern(imap, rows, cols, bs=d)
            J = self._coupled_pattern(local, patches, len(rows))

        def jacobian(x, JJ) -> None:
            self._fill_tangent(JJ, local, patches, op, op.gradients(increment(x)), c)
            JJ.zeroRowsColumnsLocal(held, diag=1.0)

        x = J.createVecRight()
        guess = (dt * v[:owned] if integ.inertia else np.zeros((owned, d))).ravel()  # constant velocity
        forces = np.concatenate([fext[:owned].ravel(), op.internal_force(op.sigma)[:owned].ravel()])
        scale = float(np.sqrt(p.comm.allreduce(float(forces @ forces))))  # what the residual balances
        moved = p.comm.allreduce(float(np.abs(p.x - p.fields["X0"]).max(initial=0.0)), op=MPI.MAX)

        def floor(xx) -> float:  # (the particles stay where they are during the solve)
            return self._round_off(J, xx, moved)

        try:
            result = self._solve(residual, jacobian, J, x, guess, scale, floor)
            if result is None:
                return False
            du = increment(x)
        finally:
            for obj in [x] + ([local, J, patches] if patches is not None else []):
                obj.destroy()
        self.last = result
        self._count_loads(op, t, dt, fext, du, owned)
        if integ.inertia:
            self._count_reactions(op, t, dt, fext, (du, v, a), m, free[:owned])
        self._update(basis, op, du, v, a, dt)
        return True

    def _loads(self, op: IncrementOperator, t: float) -> npt.NDArray:
        """The nodal external forces at time ``t`` (owned + ghost dofs, d), quasi-static ones
        scaled by the load ramp."""
        s = self.state
        f = op.nodal(external_forces(s.loads, s.particles, t))
        if not self.integration.inertia and self.options.load_ramp is not None:
            f *= min(1.0, t / self.options.load_ramp)
        return f

    @staticmethod
    def _round_off(J: PETSc.Mat, x: PETSc.Vec, moved: float) -> float:
        r"""The round-off floor of the residual's norm at the increment ``x`` with the tangent
        ``J``: :math:`c\, \epsilon\, \|J\|_\infty \max(\|x\|_\infty, \|u\|_\infty) \sqrt{N}` (``c`` =
        :data:`ROUND_OFF`, ``moved`` :math:`= \|u\|_\infty` the particles' largest displacement so
        far over all ranks, :math:`N` the unknowns): the residual is a difference of internal
        forces of about :math:`J u`, each known to about :math:`\epsilon` of that. Collective."""
        u = max(x.norm(PETSc.NormType.INFINITY), moved)
        return ROUND_OFF * np.finfo(float).eps * J.norm(PETSc.NormType.INFINITY) * u * np.sqrt(x.getSize())

    def _count_loads(self, op: IncrementOperator, t: float, dt: float, fext: npt.NDArray, du: npt.NDArray,
                     owned: int) -> None:
        r"""Add the loads' work :math:`\tfrac12 (f^n + f^{n+1}) \cdot \Delta u` and impulse
        :math:`\tfrac12 \Delta t (F^n + F^{n+1})` over the accepted (sub)step ``[t, t + dt]`` to
        the record (``fext``: the nodal loads at its end, ``du``: its increment; owned dofs,
        summed over ranks)."""
        record, comm = self.state.record, self.state.particles.comm
        mean = 0.5 * (self._loads(op, t) + fext)[:owned]
        sums = comm.allreduce(np.concatenate([[float(np.einsum("nd,nd->", mean, du[:owned]))], mean.sum(axis=0)]))
        record.load_work += float(sums[0])
        record.load_impulse = record.load_impulse + dt * sums[1:]

    def _count_reactions(self, op: IncrementOperator, t: float, dt: float, fext: npt.NDArray, motion: tuple,
                         m: npt.NDArray, free: npt.NDArray[np.bool_]) -> None:
        r"""Add what the held components took over the accepted Newmark (sub)step ``[t, t + dt]``
        to the record's ``reaction`` (this rank's owned dofs; :mod:`fempm.stepping.reactions`).
        The particles' momentum changes by :math:`\sum_a m_a (v^+_a - v_a) + (1-\alpha)
        (\sum_a m_a v_a - P^n)` with :math:`v^+ = v + \Delta t ((1-\gamma) a + \gamma a^+)`;
        at the end of the step the free rows balance, :math:`M a^+ = f^{ext} - f^{int}`, so the
        :math:`\gamma` part of what the held rows took is their residual
        :math:`\sum_{held} (f^{ext} - f^{int} - M a^+)`; the projected :math:`a` and :math:`v`
        of the particles balance only over all rows (as a mass that couples the dofs), so the
        :math:`1-\gamma` part is :math:`F^{ext}(t) - \sum_a m_a a_a` and the PIC part
        :math:`(1-\alpha)(P^n - \sum_a m_a v_a)`. ``motion``: the converged increment and the
        projected :math:`v, a` (owned + ghost dofs, d); ``m``: the lumped masses; ``free``: the
        owned dofs' free components."""
        s, integ = self.state, self.integration
        p = s.particles
        du, v, a = motion
        owned = len(free)
        a_new = integ.acceleration(du, v, a, dt)
        R = fext - op.internal_force(op.forces(op.gradients(du))) - op.mass_times(a_new, self.consistent, m)
        held = np.where(free, 0.0, R[:owned]).sum(axis=0)
        mo = m[:owned]
        old = self._loads(op, t)[:owned].sum(axis=0) - mo @ a[:owned]
        pic = (1.0 - self.options.velocity_transfer.blend) * (p.mass @ p.fields["v"] - mo @ v[:owned])
        s.record.reaction = s.record.reaction + dt * ((1.0 - integ.gamma) * old + integ.gamma * held) + pic

    def _solve(self, residual, jacobian, J: PETSc.Mat, x: PETSc.Vec, guess: npt.NDArray, scale: float, floor=None):
        """Newton from ``guess`` with the line search of the options; where it fails, once more
        with full Newton steps (``basic``: near incompressibility the first full step can raise
        the residual many times over on its way to the quadratic range, and the backtracking
        search then creeps); the :class:`~fempm.implicit.newton.NewtonResult` that converged,
        else None (:attr:`last_failure` says why). A singular quasi-static tangent stops the run.
        ``floor``: the residual's round-off floor at an iterate (:meth:`_round_off`)."""
        s = self.state
        failures = []
        for line_search in (None, "basic"):
            x.array[:] = guess
            result = self.newton.solve(residual, jacobian, J, x, force_scale=scale, line_search=line_search,
                                       floor=floor)
            s.record.newton_iterations += result.iterations
            if result.converged:
                return result
            failures.append(f"SNES {result.reason} after {result.iterations} iteration(s)"
                            + (" with full Newton steps" if line_search else ""))
            deficiency = None if self.integration.inertia else null_pivots(J)  # (with inertia the tangent is regular)
            if deficiency:  # a smaller step cannot help
                s.fail(f"singular tangent in the quasi-static step ({deficiency} null pivot(s)): a body whose "
                       "rigid motions no condition holds (give it supports, or take dynamics='newmark')")
        self.last_failure = ", then ".join(failures)
        return None

    def _fill_tangent(self, JJ: PETSc.Mat, local: PETSc.Mat, patches: PatchCoupling | None, op: IncrementOperator,
                      G: npt.NDArray, c: float) -> None:
        """The tangent at the increments ``G`` into ``JJ``: the particles' blocks (into ``local``,
        which is ``JJ`` without F-bar) and with F-bar the patch coupling (:class:`PatchCoupling`)."""
        A, coupling = op.tangents(G)
        local.setValuesCOO(op.tangent_values(A, c, self.consistent), addv=PETSc.InsertMode.INSERT_VALUES)
        local.assemble()
        if patches is not None:
            JJ.zeroEntries()
            for K in (local, *patches.products(coupling)):
                JJ.axpy(1.0, K, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)

    @staticmethod
    def _coupled_pattern(local: PETSc.Mat, patches: PatchCoupling, entries: int) -> PETSc.Mat:
        """The tangent's matrix with F-bar: the pattern of the particles' blocks (``local``, of
        ``entries`` COO entries) and of the patch coupling (the products' structure, from zero
        factors)."""
        n, d = len(patches.op.volume), patches.d
        zeros = (np.zeros((n, d, d)), np.zeros((n, d, d)), np.zeros((n, d, d)), np.zeros(n))
        local.setValuesCOO(np.zeros(entries), addv=PETSc.InsertMode.INSERT_VALUES)
        local.assemble()
        J = local.copy()
        for K in patches.products(zeros):
            J.axpy(1.0, K, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        J.setLGMap(*local.getLGMap())
        return J

    def _grid_motion(self, basis, op: IncrementOperator, free: npt.NDArray[np.bool_], m: npt.NDArray) -> npt.NDArray:
        r"""The grid velocity and acceleration of the particles' (owned + ghost dofs, 2d): the
        projection of the momenta :math:`\sum_p M_p N_a [v_p, a_p]` with the step's mass, the
        lumped :math:`m_a` or the consistent matrix (a basis with negative values, P2
        Lagrange, needs the matrix: its lumped masses vanish at the vertices); with APIC and the
        lumped mass the velocity's momenta with their affine part
        (:mod:`fempm.transfer.transfers`). Collective."""
        s = self.state
        p = s.particles
        f = p.fields
        mv = op.nodal(p.mass[:, None] * np.hstack([f["v"], f["a"]]))
        if not self.consistent:
            carried = s.affine()  # APIC: the velocity's affine part (the exact projection leaves it out)
            if carried is not None:
                mv[:, :p.gdim] += affine.affine_momentum(self.options.velocity_transfer.kind, *carried, basis,
                                                         s.dof_coordinates(), p.x, p.mass)[: len(mv)]
            return mv / np.where(m > 0, m, 1.0)[:, None]
        solve = self.options.mass_model.grid_solve(basis, p.mass, p, "mass", False)
        solve.set_up(free.any(axis=1), None, [], lambda: m, "fempm_implicit_mass_", None)
        return basis.update_ghosts(solve.solve(mv, None, basis.update_ghosts))

    def _free(self, support: npt.NDArray, num_local: int) -> npt.NDArray[np.bool_]:
        """(owned + ghost dofs, d): the components solved for: not held by a condition, on dofs
        that particles reach (``support``, :meth:`IncrementOperator.support`, above
        :data:`SUPPORT_TOL` of the largest). Not the lumped mass: the vertex functions of P2
        Lagrange on simplices integrate to zero, and their lumped masses vanish or turn negative
        where particles plainly reach them."""
        s = self.state
        d = s.particles.gdim
        free = np.ones((num_local, d), dtype=np.bool_)
        space = s.conditions.free(d)
        free[: len(space)] = space
        largest = s.particles.comm.allreduce(float(support.max(initial=0.0)), op=MPI.MAX)
        free &= (support > SUPPORT_TOL * largest)[:, None]
        return free

    def _update(self, basis, op: IncrementOperator, du: npt.NDArray, v: npt.NDArray, a: npt.NDArray, dt: float) -> None:
        """The particles after the converged increment ``du`` (see the module)."""
        s, p, integ = self.state, self.state.particles, self.integration
        f = p.fields
        if integ.inertia:
            a_new = integ.acceleration(du, v, a, dt)
            v_new = integ.velocity(v, a, a_new, dt)
            transfer = self.options.velocity_transfer
            flip = transfer.blend
            f["v"] = flip * (f["v"] + basis.gather(v_new - v)) + (1.0 - flip) * basis.gather(v_new)
            if transfer.affine:  # APIC: the affine state of the updated grid velocity
                C, spin = affine.grid_affine(transfer.kind, basis, v_new, s.dof_coordinates(), p.x,
                                             g2p.velocity_gradient(basis, v_new))
                f[AFFINE_FIELD] = C
                if spin is not None and spin.shape[1]:
                    f[SPIN_FIELD] = spin
            f["a"] = basis.gather(a_new)
            s.grid_velocity = v_new[: basis.num_dofs_space]
        else:
            f["v"] = np.zeros_like(f["v"])
            s.grid_velocity = np.zeros((basis.num_dofs_space, p.gdim))
        G = op.gradients(du)
        self.particle_stages.update_kinematics(op.law_gradients(G) / dt, dt, averaged=False)  # L dt = G
        self.particle_stages.move(basis.gather(du), lambda: basis.gather_samples(du), 1.0)
        self.particle_stages.close()
        self.particle_stages.relocate()
