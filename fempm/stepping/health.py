r"""Run health: the checks that stop a run whose state has gone wrong, and the figures that say
how healthy a finished run was.

A run of the explicit loop is stopped with a :class:`~fempm.stepping.SimulationError` naming
the cause when

* the total (kinetic + strain) energy exceeds the initial energy plus the work of the external
  loads by more than a relative tolerance,

  .. math::
      E(t) > E(0) + W(t) + \epsilon \big(E(0) + |W|(t)\big)

  (the work of moving colliders, :class:`fempm.colliders.grid.ColliderContact`, added to
  :math:`W`); the grid, its boundary conditions and the transfers of a stable explicit scheme
  do no net work, so growth is the signature of an instability (energy blow-up with a
  near-incompressible law, a step above the critical one, ringing instabilities). In an
  explicit step the work of the loads is taken with the trapezoidal rule,
  :math:`W \mathrel{+}= \tfrac12 \Delta t (f^n \cdot v^n + f^{n+1} \cdot v^{n+1})` (exact
  for a body in free flight: the reported ratio), and the check allows the larger of that and
  the work along the step's motion, :math:`\Delta t\, f \cdot v^{n+1}` (the particles move
  with the updated velocity): from rest the trapezoidal rule counts half of the first step's
  work, and the strain energy that step stores looked like a growth of :math:`(\omega \Delta
  t)^2` (24 % for P2 consistent mass on Cook's membrane); the two differ by
  :math:`\tfrac12 \Delta t\, f \cdot (v^n - v^0)` only. An implicit step reports the work of
  its nodal loads over its displacement increment, :math:`\tfrac12 (f^n + f^{n+1}) \cdot
  \Delta u` (:attr:`fempm.stepping.solver.StepRecord.load_work`; exact for a load ramped
  linearly on a linear body, and for Newmark's average acceleration). Quasi-static steps are
  not checked (their energy ratio is reported: the strain energy over that work, 1 for an
  elastic body loaded slowly);
* the volume ratio :math:`J = \det F` of a particle leaves :math:`[J_{min}, J_{max}]` (a
  collapsed or torn-apart particle no longer represents continuum);
* the time step falls below ``dt_floor`` times the first step, or no longer advances time.

The :meth:`HealthMonitor.summary` records the outcome and the energy ratio
:math:`E(t)/(E(0) + W(t))`, the momentum drift
:math:`|P(t) - P(0) - I(t) + R(t) + J(t)| / \max_s \sum_p M_p |v_p|(s)` (with :math:`I` the
impulse of the external loads and of the grid damping, :math:`R` the reactions of the grid conditions, the momentum
the supports and walls took (:mod:`fempm.stepping.reactions`, ``reaction_impulse``), and
:math:`J` the impulse the colliders took: round-off where these are the only external actions;
a figure, not a check; an implicit Newmark step counts its held components' reactions,
:meth:`fempm.implicit.step.ImplicitStep._count_reactions`) and the range of :math:`J = \det F`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.stepping import diagnostics
from fempm.stepping.loads import external_forces

__all__ = ["SMALL_STRAIN_ROTATION", "Health", "HealthMonitor"]

#: the rotation (degrees) of a small-strain body beyond which the energy check's message points
#: at the law: a rotation theta stores the energy of a strain of about 1 - cos(theta)
SMALL_STRAIN_ROTATION = 10.0


@dataclass(frozen=True)
class Health:
    r"""Limits of a healthy run; a crossed one stops it.

    Args:
        energy_tolerance: The relative growth of the energy beyond the work of the loads that
            stops the run (None: no energy check, for scenes that inject energy on purpose or
            whose stored energy does not describe their initial state).
        j_min: The smallest volume ratio J a particle may reach.
        j_max: The largest volume ratio J a particle may reach.
        dt_floor: The smallest time step, as a fraction of the first one.

    Why 20 %: the explicit update is symplectic Euler, whose computed energy (kinetic energy of
    :math:`v^{n+1}` plus strain energy of :math:`F^{n+1}`) oscillates about a conserved shadow
    energy by up to :math:`\omega \Delta t / 2` of the energy in the highest excited modes.
    Stable runs of the stability catalogue (``python -m fempm study stability --quick``, run
    without the energy check) peak at 6-10 % above their budget during impacts (MUSL:
    near-empty cells 6.1 %, slivers 9.8 %, one particle per cell 6.1 %) and settle back; the unstable ones grow without bound (x2 to x18
    before they invert), so 20 % separates the two with margin on both sides."""

    energy_tolerance: float | None = 0.2
    j_min: float = 1e-2
    j_max: float = 1e2
    dt_floor: float = 1e-6

    def __post_init__(self):
        if self.energy_tolerance is not None and not self.energy_tolerance > 0:
            raise ValueError(f"energy_tolerance={self.energy_tolerance} must be > 0 (or None: no energy check)")
        if not 0.0 <= self.j_min < 1.0 < self.j_max:
            raise ValueError(f"J bounds [{self.j_min}, {self.j_max}] must satisfy 0 <= j_min < 1 < j_max")
        if not 0.0 <= self.dt_floor < 1.0:
            raise ValueError(f"dt_floor={self.dt_floor} must lie in [0, 1)")

    def asdict(self) -> dict:
        return asdict(self)


class HealthMonitor:
    """Watches an :class:`~fempm.stepping.ExplicitSolver` step by step (:meth:`after_step`),
    raising :class:`~fempm.stepping.SimulationError` when a :class:`Health` limit is crossed."""

    def __init__(self, solver, health: Health | None = None):
        self.solver = solver
        self.health = health or Health()
        e = solver.energies()
        self.e0 = e["total"]
        self.e_max = self.e0
        self.momentum0 = self._momentum()
        self.total_mass = solver.particles.comm.allreduce(float(np.sum(solver.particles.mass)))
        self.work = 0.0
        self.work_path = 0.0  # explicit: along the steps' motion (the check's other measure)
        self.impulse = np.zeros_like(self.momentum0)
        self.reactions = np.zeros_like(self.momentum0)  # what the grid conditions took
        self._power, self._force = self._external(solver.t, self.momentum0)
        self.first_dt: float | None = None
        self._t_prev = solver.t
        self.j_min, self.j_max = self._j_range()
        self.p_scale = diagnostics.momentum_scale(self.solver.particles)
        self.drift = 0.0
        self.ratio = 1.0
        self.outcome = "running"
        self.error: str | None = None
        #: whether the energy check applies: not to quasi-static implicit steps (their ratio of the
        #: strain energy to the loads' work is reported)
        integration = solver.options.integration
        self.checks_energy = integration is None or integration.inertia

    #: the attributes that accumulate over a run (:meth:`state_dict`)
    KEPT = ("e0", "e_max", "momentum0", "work", "work_path", "impulse", "reactions", "_power", "_force",
            "first_dt", "_t_prev", "j_min", "j_max", "p_scale", "drift", "ratio", "total_mass")

    def state_dict(self) -> dict:
        """What a continued run's checks need: the sums and references of :attr:`KEPT` (JSON
        values, the same on every rank)."""
        values = {k: getattr(self, k) for k in self.KEPT}
        return {k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in values.items()}

    def load_state_dict(self, state: dict) -> None:
        """Restore :meth:`state_dict` (lists back to arrays).

        Raises:
            ValueError: A state lacking one of :attr:`KEPT`.
        """
        missing = [k for k in self.KEPT if k not in state]
        if missing:
            raise ValueError(f"the run-health state lacks {', '.join(missing)}")
        for k in self.KEPT:
            v = state[k]
            setattr(self, k, np.asarray(v) if isinstance(v, list) else v)

    # -- measures ------------------------------------------------------------------------------
    def _momentum(self) -> npt.NDArray:
        p = self.solver.particles
        return p.comm.allreduce(p.mass @ p.fields["v"])

    def _j_range(self) -> tuple[float, float]:
        p = self.solver.particles
        J = np.linalg.det(p.fields["F"]) if len(p) else np.ones(1)
        lo = p.comm.allreduce(float(J.min(initial=np.inf)), op=MPI.MIN)
        return lo, p.comm.allreduce(float(J.max(initial=-np.inf)), op=MPI.MAX)

    def _external(self, t: float, momentum: npt.NDArray, removed: float = 0.0) -> tuple[float, npt.NDArray]:
        r"""Power :math:`\sum_p f_p(t) \cdot v_p` and resultant :math:`\sum_p f_p(t)` of the
        external loads at time ``t`` (body forces and tractions) on the particles' velocities
        now, summed over ranks; a constant body force :math:`g`: :math:`g \cdot \sum_p M_p v_p`
        and :math:`g \sum_p M_p` from the particles' ``momentum``, without a pass over the
        particles (``removed``: the mass that left the mesh in the last step, still counted)."""
        p = self.solver.particles
        loads = self.solver.loads
        if not loads.per_particle:
            if loads.body_force is None:
                return 0.0, np.zeros(p.gdim)
            g = np.asarray(loads.body_force, dtype=np.float64)
            return float(g @ momentum), g * (self.total_mass - self.solver.removed.mass + removed)  # the mass here
        f = external_forces(loads, p, t)
        local = np.concatenate([[np.einsum("nd,nd->", f, p.fields["v"])], f.sum(axis=0)])
        total = p.comm.allreduce(local)
        return float(total[0]), total[1:]

    # -- the check -----------------------------------------------------------------------------
    def after_step(self, dt: float, energies: dict, *, final: bool = False,
                   momentum_scale: float | None = None) -> None:
        r"""Update the measures after a step of size ``dt`` that led to ``energies``
        (:meth:`ExplicitSolver.energies`) and raise when a limit is crossed. ``final``: the
        step that was shortened to end at ``t_end`` (exempt from the step floor);
        ``momentum_scale``: :math:`\sum_p M_p |v_p|` of the state when known
        (:meth:`ExplicitSolver.step_energies`), else computed."""
        s, h = self.solver, self.health
        mom = np.array([energies[k] for k in energies if k.startswith("momentum_")])
        if s.options.integration is not None:  # the implicit step's own account of its loads
            self.work += s.record.load_work
            self.work_path += s.record.load_work
            self.impulse = self.impulse + s.record.load_impulse
        else:  # the loads at the step's end on the particles in the mesh; those removed in this step were in it
            power, force = self._external(s.t, mom)  # until its end
            end = self._external(s.t, mom + s.removal.last_momentum, s.removal.last_mass) if s.removal.removed_now \
                else (power, force)
            self.work += 0.5 * dt * (self._power + end[0])
            self.work_path += dt * end[0]
            self.impulse = self.impulse + 0.5 * dt * (self._force + end[1])
            self._power, self._force = power, force
        gone = s.removed  # what the particles that left the mesh took: it has left, not vanished
        if gone.count:
            mom = mom + np.asarray(gone.momentum)
        rec = s.record
        if rec.reaction.size or rec.damping_impulse.size:  # (collective: the same conditions and damping on every rank)
            d = len(mom)
            local = np.concatenate([rec.reaction if rec.reaction.size else np.zeros(d),
                                    rec.damping_impulse if rec.damping_impulse.size else np.zeros(d)])
            total = s.particles.comm.allreduce(local)
            self.reactions = self.reactions + total[:d]  # what the supports and walls took
            self.impulse = self.impulse + total[d:]  # the damping's, an external action as the loads'
            rec.reaction, rec.damping_impulse = np.zeros(0), np.zeros(0)
        mom = mom + s.collisions.total_impulse + self.reactions  # what the colliders and the conditions took
        e = energies["total"] + gone.kinetic + gone.strain
        self.e_max = max(self.e_max, e)
        budget = self.e0 + self.work + s.collisions.total_work
        self.ratio = e / budget if budget > 0 else (1.0 if e <= 0 else np.inf)
        allowed = budget + max(0.0, self.work_path - self.work)  # the larger measure of the loads' work
        if momentum_scale is None:
            momentum_scale = diagnostics.momentum_scale(s.particles)
        self.p_scale = max(self.p_scale, momentum_scale)
        self.drift = float(np.linalg.norm(mom - self.momentum0 - self.impulse) / self.p_scale) if self.p_scale > 0 else 0.0
        lo, hi = s.j_range if s.j_range is not None else self._j_range()
        self.j_min, self.j_max = min(self.j_min, lo), max(self.j_max, hi)
        if self.first_dt is None:
            self.first_dt = dt
        if h.energy_tolerance is not None and self.checks_energy:
            scale = self.e0 + abs(self.work) if self.e0 + abs(self.work) > 0 else self.e_max  # from rest: the peak
            if e > allowed + h.energy_tolerance * scale and scale > 0:
                s.fail(self._growth_message(e, allowed, scale, gone))
        if lo < h.j_min or hi > h.j_max:
            s.fail(f"volume ratio J = det F = {lo if lo < h.j_min else hi:.3g} left the bounds [{h.j_min:g}, {h.j_max:g}]")
        stalled, self._t_prev = s.t <= self._t_prev, s.t
        if not final and (dt < h.dt_floor * self.first_dt or stalled):
            s.fail(f"time step collapse: dt = {dt:.3g} is below {h.dt_floor:g} of the first step "
                    f"{self.first_dt:.3g} or no longer advances time")

    def _growth_message(self, e: float, budget: float, scale: float, gone) -> str:
        """What the energy check says: every term of the budget; with pure FLIP and a frictional
        or curved wall, the blend that keeps it; where a small-strain law turned far, that its stored energy
        is not meant for that (collective)."""
        s = self.solver
        terms = [f"the initial energy {self.e0:.6g}", f"the work of the loads {max(self.work, self.work_path):.6g}"]
        if len(s.collisions):
            terms.append(f"the work of the colliders {s.collisions.total_work:.6g}")
        held = f" (with the {gone.kinetic + gone.strain:.6g} the removed particles took)" if gone.count else ""
        message = (f"energy growth: the total energy {e:.6g}{held} exceeds its budget {budget:.6g} = "
                   f"{' + '.join(terms)} by {100 * (e - budget) / scale:.3g} % (tolerance "
                   f"{100 * self.health.energy_tolerance:g} %): the run is unstable")
        if s.options.velocity_transfer.blend == 1.0 and (s.conditions.frictional or s.conditions.curved):
            message += ("; pure FLIP (flip = 1) gains energy where a body rolls or slides along a curved wall, "
                        "frictional or not (docs/boundaries.md, 'Friction on a curved wall'): take a blend, e.g. "
                        "flip = 0.99")
        angle = diagnostics.small_strain_rotation(s.particles, s.materials)
        if angle > SMALL_STRAIN_ROTATION:
            message += (f"; or a small-strain law (LinearElastic) has turned by up to {angle:.3g} degrees, which its "
                        "stored energy takes for strain: take a finite-strain law (NeoHookean) for large rotations")
        return message

    def summary(self) -> dict:
        return {
            "outcome": self.outcome, "error": self.error, "energy_ratio": self.ratio, "momentum_drift": self.drift,
            "j_min": self.j_min, "j_max": self.j_max, "external_work": self.work,
            "reaction_impulse": self.reactions.tolist(), "limits": self.health.asdict(),
        }
