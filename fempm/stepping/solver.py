r"""The explicit MPM solver: the particle state's owner, and the step as the stages of the cycle.

:meth:`ExplicitSolver.step` opens the grid (P2G and the stable time step), chooses the time step,
runs the stages of the scheme (:mod:`fempm.stepping.schemes`: grid update, G2P, kinematics,
stress, motion) on the grid (:mod:`fempm.stepping.grid`: one velocity field, a field per body
with contact, or compiled passes for point particles on degree-1 cells), closes it and
advances the time. The equations are in :mod:`fempm.stepping.grid`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Literal

import dolfinx.fem
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.boundary.conditions import GridConditions
from fempm.colliders.grid import ColliderContact
from fempm.materials.base import check_materials, identity
from fempm.meshes.cell_sizes import cell_sizes
from fempm.particles.particle_set import Particles
from fempm.stepping import checks, diagnostics
from fempm.stepping.contact import Contact
from fempm.stepping.fbar import check_laws
from fempm.stepping.grid import Grid, SingleFieldGrid
from fempm.stepping.grid_choice import choose_grid
from fempm.stepping.loads import Loads
from fempm.stepping.options import StepOptions
from fempm.stepping.outside import Outside, Removed
from fempm.stepping.record import StepRecord
from fempm.stepping.state import StepState
from fempm.transfer import affine
from fempm.transfer.basis import ParticleBasis
from fempm.transfer.transfers import AFFINE_FIELD, SPIN_FIELD

__all__ = ["ExplicitSolver", "Solver", "StepRecord", "register_implicit_step"]


#: the maker of the implicit step (see :func:`register_implicit_step`)
_IMPLICIT_STEP: list[Callable] = []


def _state_member(name: str, doc: str) -> property:
    """The solver's attribute ``name``: its :class:`StepState`'s, read and set."""
    return property(lambda self: getattr(self.state, name), lambda self, value: setattr(self.state, name, value),
                    doc=doc)


def register_implicit_step(maker: Callable) -> None:
    """Make the implicit step of a solver with ``maker(state)`` (its :class:`StepState`), an object whose
    ``step(dt) -> dt`` advances the particles (:class:`fempm.implicit.step.ImplicitStep`;
    :mod:`fempm.implicit` registers it when imported, and ``import fempm`` imports that), so
    that the explicit step's package does not import the implicit one."""
    _IMPLICIT_STEP[:] = [maker]


class Solver:
    """MPM on a vector Lagrange space (degree 1 or 2, or Bernstein) of the particles' mesh: it
    owns the state and steps it explicitly or, with ``StepOptions(integrator="implicit")``,
    implicitly (``ExplicitSolver`` is the same class, the name of existing code).

    :meth:`step` is one cycle: map the particles to the grid, solve for the grid velocity with
    the mass model, apply the grid conditions (and contact), update the particles, relocate
    them. The particles' state lives in ``particles.fields``: ``v`` (n, d), ``F`` (n, d, d),
    ``sigma`` (n, d, d), ``volume0`` (n,), ``body`` (n,) an index into ``materials``, and the
    reference positions ``X0`` (n, d) (the positions when the solver is made, unless given).

    Args:
        V: The velocity space.
        particles: The particles.
        materials: The laws (:mod:`fempm.materials`), one per value of ``fields["body"]``.
        bcs: The grid conditions (:mod:`fempm.boundary`).
        loads: Body forces and tractions (keyword, as every argument after ``bcs``; None: none).
        options: The step's options (scheme, mass model, particle domain, FLIP blend, CFL; None: the defaults).
        t: The start time.
        step_count: The steps taken before (a continued run).
        compiled: Take the compiled passes where they apply (None, the default: a degree-1
            space on cells with straight edges, with point particles and lumped, consistent or
            FMPM mass, or on affine cells CPDI1 or Gauss-rule GIMP domains and lumped mass), insist on them (True: an
            error where they do not apply) or never (False: the numpy step, which is their
            reference).
        contact: One velocity field per particle group with frictional contact between them
            (:class:`fempm.stepping.contact.Contact`); None: one field for all.
        outside: What a particle that leaves the mesh does (:mod:`fempm.stepping.outside`):
            ``"raise"`` an error naming it, ``"remove"`` it is dropped and what it takes
            accounted (:attr:`removed`).
        colliders: Rigid obstacles given as shapes in prescribed motion
            (:class:`fempm.colliders.Collider`), acting on the velocity update; their positions
            and reactions are :attr:`collisions` (:class:`fempm.colliders.grid.ColliderContact`).

    Raises:
        ValueError: Options, fields or conditions that do not fit the space or the particles.

    Note:
        Construction and :meth:`step` are collective.
    """

    def __init__(self, V: dolfinx.fem.FunctionSpace, particles: Particles, materials: Sequence, bcs: Sequence = (),
                 *, loads: Loads | None = None, options: StepOptions | None = None, t: float = 0.0, step_count: int = 0,
                 compiled: bool | None = None, contact: Contact | None = None, outside: str = "raise",
                 colliders: Sequence = ()):
        p = particles
        if V.mesh is not p.mesh:
            raise ValueError("the particles were made on another mesh than the velocity space's: make them on V.mesh "
                             "(fempm.create_particles(V.mesh, ...) or fempm.Particles(V.mesh, ...))")
        loads = Loads() if loads is None else loads
        options = StepOptions() if options is None else options
        check_materials(materials)
        if options.volumetric_average is not None:
            check_laws(materials)
        d = p.gdim
        n = len(p)
        f = p.fields
        f.setdefault("v", np.zeros((n, d)))
        f.setdefault("F", identity(n, d))
        f.setdefault("sigma", np.zeros((n, d, d)))
        f.setdefault("volume0", p.volume.copy())
        f.setdefault("body", np.zeros(n, dtype=np.int32))
        f.setdefault("X0", p.x.copy())  # reference positions (body forces b(X, t), error norms)
        for mat in materials:  # the laws' internal variables (fempm.materials.base.Internal)
            for h in mat.history:
                expected = (n, *h.shape_for(d))
                if np.shape(f.setdefault(h.name, h.allocate(n, d))) != expected:
                    raise ValueError(f"internal variable {h.name!r} of {type(mat).__name__} has shape "
                                     f"{np.shape(f[h.name])}; expected {expected}")
        checks.check_fields(p, materials)
        self.bcs, self.outside, self.colliders = bcs, outside, colliders
        h_cell = cell_sizes(p.mesh)
        collisions = ColliderContact(V, colliders, h_cell, t)
        conditions = GridConditions(V, [*bcs, *([collisions] if colliders else [])])
        #: what the step's parts read and update (:class:`fempm.stepping.state.StepState`)
        self.state = StepState(V, p, materials, loads, options, conditions, collisions, contact, compiled, h_cell,
                               Outside(outside), StepRecord(), t=t, step_count=step_count)
        self._stress_space: dolfinx.fem.FunctionSpace | None = None  # tensor space of grid_stress, on first use
        self._grid: Grid | None = None
        self._grid_key: tuple | None = None
        self._implicit: tuple | None = None  # (id of the options, ImplicitStep)
        if options.integration is not None:
            self.implicit  # noqa: B018 - made now: what the implicit step cannot take is an error before any step

    # the state's members, read and set as the solver's
    V = _state_member("V", "The velocity space.")
    particles = _state_member("particles", "The particles.")
    materials = _state_member("materials", "The laws, one per body.")
    loads = _state_member("loads", "Body forces and tractions.")
    options = _state_member("options", "The step's options (setting them remakes the grid at the next step).")
    compiled = _state_member("compiled", "Whether the compiled passes are asked for (None: where they apply).")
    contact = _state_member("contact", "Multi-field contact (None: one field).")
    conditions = _state_member("conditions", "The grid conditions (the colliders among them).")
    collisions = _state_member("collisions", "The colliders' contact and reactions.")
    h_cell = _state_member("h_cell", "The cells' sizes (the CFL lengths).")
    removal = _state_member("removal", "The policy for particles that leave the mesh, and what they took.")
    record = _state_member("record", "What the steps report (:class:`StepRecord`).")
    t = _state_member("t", "The time.")
    step_count = _state_member("step_count", "The steps taken.")
    grid_velocity = _state_member("grid_velocity", "The last step's grid velocity (owned + ghost dofs, d), None before.")

    # the record's entries, read as the solver's
    terms = property(lambda self: self.record.terms)
    j_range = property(lambda self: self.record.j_range)
    mass_ratio = property(lambda self: self.record.mass_ratio)
    extended_steps = property(lambda self: self.record.extended_steps)

    # -- the state's checks (StepState's) ---------------------------------------------------------
    def particle_ids(self, mask: npt.NDArray[np.bool_]) -> list[int]:
        """The ids of the first (up to 5) particles of ``mask`` over all ranks (collective)."""
        return self.state.particle_ids(mask)

    def fail(self, what: str):
        """Raise a :class:`~fempm.stepping.SimulationError` naming this step and time."""
        self.state.fail(what)

    def check_state(self) -> None:
        """The particle fields' shapes, a finite state and every body index a material (collective)."""
        self.state.check_state()

    def check_finite(self) -> None:
        """A finite state at every particle, else a :class:`~fempm.stepping.SimulationError` (collective,
        :meth:`StepState.check_finite`)."""
        self.state.check_finite()

    # -- the step -----------------------------------------------------------------------------
    def stable_dt(self) -> float:
        """The stable lumped-mass time step of the state now (:meth:`StepState.stable_dt`). Collective."""
        return self.state.stable_dt()

    @property
    def grid(self) -> Grid:
        """The grid of the step (made on first use, remade when the options, ``compiled`` or
        ``contact`` change): with contact a :class:`~fempm.stepping.contact_points.ContactPointGrid`
        where its compiled passes apply, else a :class:`~fempm.stepping.contact.ContactGrid`; a
        :class:`~fempm.stepping.lumped.PointGrid` or a
        :class:`~fempm.stepping.domain_grid.DomainGrid` where the compiled passes apply (unless
        ``compiled=False``), else a :class:`~fempm.stepping.grid.SingleFieldGrid`."""
        key = (id(self.options), self.compiled, id(self.contact))
        if self._grid is None or self._grid_key != key:
            self._grid, self._grid_key = choose_grid(self.state), key
        return self._grid

    @property
    def implicit(self):
        """The implicit step (``StepOptions(integrator="implicit")``,
        :class:`fempm.implicit.step.ImplicitStep`, as :func:`register_implicit_step` gave it),
        made on first use and remade when the options change."""
        if self._implicit is None or self._implicit[0] != id(self.options):
            if not _IMPLICIT_STEP:
                raise RuntimeError("the implicit step is not registered: import fempm (it imports fempm.implicit)")
            self._implicit = (id(self.options), _IMPLICIT_STEP[0](self.state))
        return self._implicit[1]

    def step(self, dt: float | None = None, *, dt_max: float = np.inf, totals: bool = False) -> float:
        """Advance one step; returns the ``dt`` used. ``dt`` defaults to the stable step
        (at most ``dt_max``); a given ``dt`` above the stability limit (CFL > 1) is an error.
        ``totals``: the particle passes also sum the energies and momentum of the new state,
        for :meth:`step_energies` (a run's every step; a few per cent of a pass).

        Note:
            Collective.
        """
        if self.removed.count and self.particles.num_global == 0:
            self.fail(f"every particle has left the mesh ({self.removed.count} removed, mass {self.removed.mass:.6g})")
        checks.check_step_arguments(self.particles, dt, dt_max)
        if self.options.integration is not None:  # implicit
            dt = self.implicit.step(dt)
            self.t += dt
            self.step_count += 1
            return dt
        grid = self.grid.for_step()
        grid.totals = totals
        stable = grid.open(dt)
        dt = self._time_step(stable, dt, dt_max)
        self.collisions.begin(self.t, dt)
        v_new = self.options.stages.update(grid, dt)
        grid.close()
        self.collisions.end(dt)
        self.state.t += dt
        self.state.step_count += 1
        grid.relocate()
        self.state.grid_velocity = grid.nodal(v_new)
        return dt

    def _time_step(self, stable: float, dt: float | None, dt_max: float) -> float:
        """The step: ``dt`` if given (an error above the stability limit, CFL > 1), else the
        ``stable`` one, at most ``dt_max``; either way no collider moves more than the CFL
        number (given: 1) times the smallest cell in it (:meth:`ColliderContact.max_step`)."""
        cfl = self.options.cfl
        if dt is None:
            dt = min(stable, dt_max)
            if not np.isfinite(dt):
                raise ValueError("no stable time step: every particle is at rest and its law has wave speed 0; "
                                 "give dt or dt_max")
            dt = self.collisions.max_step(self.t, dt, cfl)
        elif dt > stable / cfl:
            self.fail(f"time step {dt:.3g} exceeds the stability limit {stable / cfl:.3g} (CFL > 1)")
        elif self.collisions.max_step(self.t, dt, 1.0) < dt:
            self.fail(f"time step {dt:.3g} lets a collider move more than the smallest cell "
                      f"({self.collisions.h_min:.3g}) in one step: it could pass through a body")
        if not self.t + dt > self.t:  # e.g. a particle at 1e200 m/s: the stable step underflows
            self.check_finite()  # collective: names a non-finite velocity first
            self.fail(f"time step collapse: dt = {dt:.3g} does not advance t = {self.t:.6g}")
        return dt

    def mapped_velocity(self) -> npt.NDArray:
        """The grid velocity of the present particle state, (owned + ghost dofs, d): P2G of the
        momenta and the step's mass solve and constraints (the first stage of a step), nothing
        advanced. The grid frame at t = 0 of :func:`fempm.scene.run`. Collective."""
        return SingleFieldGrid(self.state).initial_velocity()

    def state_dict(self) -> dict:
        """What a continued run needs to repeat the next steps bit for bit: the time, the step
        count, the step record's running entries (:meth:`StepRecord.state_dict`), what removed
        particles took and the colliders' state (their ``state_dict``), the grid's counters, and
        under ``"arrays"`` this rank's arrays (the last grid velocity, the grid's warm starts and
        kept systems, :meth:`fempm.stepping.grid.Grid.checkpoint_state`). Every other value is
        JSON and the same on every rank. The particles are not part of it."""
        counters, arrays = self._grid.checkpoint_state() if self._grid is not None else ({}, {})
        if self.grid_velocity is not None:
            arrays = {"grid_velocity": self.grid_velocity, **arrays}
        return {"t": self.t, "step_count": self.step_count, **self.record.state_dict(),
                "since_sort": counters.get("since_sort"), "ratio_age": counters.get("ratio_age"),
                "removed": self.removal.state_dict(), "colliders": self.collisions.state_dict(), "arrays": arrays}

    def load_state_dict(self, state: dict) -> None:
        """Restore :meth:`state_dict` into a solver built on the restored particles; ``"arrays"``
        may be empty (a continuation on another number of ranks starts the grid afresh).

        Note:
            Collective.
        """
        arrays = dict(state.get("arrays", {}))
        self.t, self.step_count = float(state["t"]), int(state["step_count"])
        self.record.load_state_dict(state)
        if "removed" in state:
            self.removal.load_state_dict(state["removed"])
        if "colliders" in state:
            self.collisions.load_state_dict(state["colliders"])
        self.grid_velocity = arrays.pop("grid_velocity", None)
        self.grid.restore_state({"since_sort": state.get("since_sort"), "ratio_age": state.get("ratio_age")}, arrays)

    # -- diagnostics --------------------------------------------------------------------------
    def grid_stress(self, mass: Literal["lumped", "consistent"] | None = None) -> dolfinx.fem.Function:
        """The Cauchy stress on the grid, a tensor Lagrange Function of ``V``'s degree and variant
        (:func:`fempm.stepping.diagnostics.grid_stress`; the space is made on first use).

        Note:
            Collective.
        """
        if self._stress_space is None:
            self._stress_space = diagnostics.stress_space(self.V)
        return diagnostics.grid_stress(self._stress_space, self.particles, self.options, mass)

    @property
    def removed(self) -> Removed:
        """What the particles removed from the mesh took (``outside="remove"``), over the run."""
        return self.removal.removed

    def relocate_particles(self, left: npt.NDArray[np.bool_] | None = None) -> None:
        """Locate the moved particles under the ``outside`` policy (:meth:`StepState.relocate_particles`). Collective."""
        self.state.relocate_particles(left)

    def energies(self) -> dict[str, float]:
        """Kinetic, strain and total energy and linear momentum (:func:`fempm.stepping.diagnostics.energies`),
        with ``outside="remove"`` also what the removed particles took (:meth:`Removed.columns`),
        with colliders their forces, impulses and displacements (:meth:`ColliderContact.columns`).

        Note:
            Collective.
        """
        return {**diagnostics.energies(self.particles, self.materials, self.t), **self.angular_momentum(),
                **self.removal.columns(), **self.collisions.columns()}

    def set_velocity_gradient(self, gradient: npt.ArrayLike) -> None:
        r"""Start the particles' affine state from their velocity gradient :math:`\nabla v`
        (one (d, d) or one per particle, (n, d, d)): :math:`C_p = \nabla v` and, for APIC, the
        spin :math:`\epsilon : (\nabla v\, D_p)^T` at the particles' positions; nothing for the
        transfers without (:mod:`fempm.transfer.transfers`). Without it the state starts at 0
        (the first P2G is PIC's).

        Raises:
            ValueError: A gradient of another shape.

        Note:
            Collective.
        """
        s = self.state
        p = s.particles
        d = p.gdim
        grad = np.asarray(gradient, dtype=np.float64)
        if grad.shape not in ((d, d), (len(p), d, d)):
            raise ValueError(f"the velocity gradient has shape {grad.shape}; expected ({d}, {d}) or ({len(p)}, {d}, {d})")
        state = s.affine(check=True)
        if state is None:
            return
        grad = np.array(np.broadcast_to(grad, (len(p), d, d)), order="C")  # (writable: the passes update it)
        p.fields[AFFINE_FIELD] = grad
        if state[1] is not None:
            basis = ParticleBasis(s.V, p, domain=s.options.particle_domain)
            p.fields[SPIN_FIELD] = affine.spin_of(grad @ affine.second_moments(basis, s.dof_coordinates(), p.x))

    def angular_momentum(self) -> dict[str, float]:
        r"""The particles' angular momentum about the origin with the affine part the grid map
        carries (APIC, TPIC: :meth:`fempm.stepping.state.StepState.affine_spin`), as the
        columns of :func:`fempm.stepping.diagnostics.angular_columns` (none in 1D).

        Note:
            Collective.
        """
        return diagnostics.angular_columns(self.particles, self.state.affine_spin())

    def step_energies(self) -> tuple[dict[str, float], float]:
        r"""(:meth:`energies`, the momentum scale :math:`\sum_p M_p |v_p|`) of the state the last
        step left: from the sums its particle passes accumulated in a step with ``totals`` where
        the grid keeps them (:meth:`fempm.stepping.grid.Grid.state_sums`: one reduction, no pass
        over the particles), else from the state. Call it right after :meth:`step`: the sums do not see a state
        changed after the step (:meth:`energies` does).

        Note:
            Collective.
        """
        p = self.particles
        sums = self._grid.state_sums() if self._grid is not None and not self.removal.removed_now else None
        if sums is None:  # the same grid on every rank (and the step's sums hold particles removed since)
            return self.energies(), diagnostics.momentum_scale(p)
        p.comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
        row = diagnostics.energy_row(self.t, sums[0], sums[1], sums[3:])
        return {**row, **self.angular_momentum(), **self.removal.columns(), **self.collisions.columns()}, float(sums[2])


#: the solver's name in existing code (the same class)
ExplicitSolver = Solver
