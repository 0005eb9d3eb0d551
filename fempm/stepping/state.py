r"""What the parts of a step read and update: :class:`StepState`.

The grids (:mod:`fempm.stepping.grid` and the compiled ones), the particle stages, the choice of
grid, the nodal masses (through their grid) and the implicit step take a :class:`StepState`:
the space, particles, laws, loads, options and conditions, the step's record and time, and the
checks and hooks they call (failing collectively, relocating the particles). The solver
(:class:`fempm.stepping.Solver`) owns one and reads its time and record from it; none of the
parts holds the solver.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import dolfinx.fem
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.boundary.conditions import GridConditions
from fempm.colliders.grid import ColliderContact
from fempm.particles.particle_set import Particles
from fempm.stepping import checks
from fempm.stepping.contact_options import Contact
from fempm.stepping.laws import material_groups
from fempm.stepping.loads import Loads
from fempm.stepping.options import SimulationError, StepOptions
from fempm.stepping.outside import Outside
from fempm.stepping.record import StepRecord
from fempm.transfer import affine
from fempm.transfer.basis import ParticleBasis
from fempm.transfer.transfers import AFFINE_FIELD, SPIN_FIELD

__all__ = ["StepState"]


@dataclass(eq=False)
class StepState:
    """The state a step reads and updates, and the checks and hooks its parts call.

    Attributes:
        V: The velocity space.
        particles: The particles.
        materials: The laws, one per body.
        loads: Body forces and tractions.
        options: The step's options.
        conditions: The grid conditions (the colliders among them).
        collisions: The colliders' contact and reactions.
        contact: Multi-field contact (None: one field).
        compiled: Whether the compiled passes are asked for (None: where they apply).
        h_cell: The cells' sizes (the CFL lengths).
        removal: The policy for particles that leave the mesh, and what they took.
        record: What the steps report.
        t: The time.
        step_count: The steps taken.
        grid_velocity: The last step's grid velocity (owned + ghost dofs, d), None before.
    """

    V: dolfinx.fem.FunctionSpace
    particles: Particles
    materials: Sequence
    loads: Loads
    options: StepOptions
    conditions: GridConditions
    collisions: ColliderContact
    contact: Contact | None
    compiled: bool | None
    h_cell: npt.NDArray
    removal: Outside
    record: StepRecord
    t: float = 0.0
    step_count: int = 0
    grid_velocity: npt.NDArray | None = None
    _dof_coordinates: npt.NDArray | None = field(default=None, repr=False)

    def particle_ids(self, mask: npt.NDArray[np.bool_]) -> list[int]:
        """The ids of the first (up to 5) particles of ``mask`` over all ranks (collective)."""
        ids = np.concatenate(self.particles.comm.allgather(self.particles.ids[mask][:5]))
        return ids[:5].tolist()

    def fail(self, what: str):
        """Raise a :class:`~fempm.stepping.SimulationError` naming this step and time (call it on
        every rank: the checks that lead to it are collective)."""
        raise SimulationError(f"step {self.step_count}, t = {self.t:.6g}: {what}")

    def check_state(self) -> None:
        """The particle fields' shapes, a finite state and every body index a material (collective)."""
        checks.check_fields(self.particles, self.materials)
        self.check_finite()
        checks.check_bodies(self.particles, self.materials, self.particle_ids)

    def check_finite(self) -> None:
        r"""Positions, stresses and the kinetic energy density :math:`v_p \cdot v_p` (hence the
        velocities) finite at every particle, else a :class:`~fempm.stepping.SimulationError`
        (collective)."""
        bad = checks.nonfinite_particles(self.particles)
        if self.particles.comm.allreduce(int(bad.sum())):
            self.fail(f"non-finite state at particle(s) {self.particle_ids(bad)}")

    def count_terms(self) -> None:
        """Count the force terms assembled this step (the record's ``terms``)."""
        self.record.terms["internal"] += 1
        self.record.terms.update(k for k in ("body_force", "traction") if getattr(self.loads, k) is not None)
        if self.loads.surface:
            self.record.terms["surface"] += 1

    def stable_dt(self) -> float:
        r""":math:`\Delta t = \mathrm{CFL}\, \min_p h_{c(p)} / (c_p + |v_p|)` over all ranks: the
        lumped-mass step. The grid multiplies it by its mass model's factor
        (:meth:`fempm.transfer.mass_models.MassModel.stable_factor`). Collective."""
        p = self.particles
        f = p.fields
        rho = p.mass / p.volume
        c = np.zeros(len(p))
        for mat, idx in material_groups(f, self.materials):
            c[idx] = mat.wave_speed(f["F"][idx], rho[idx])
        speed = c + np.linalg.norm(f["v"], axis=1)
        moving = ~(speed <= 0)  # particles at rest with no wave speed set no limit (NaN stays)
        local = np.min(self.h_cell[p.cells][moving] / speed[moving], initial=np.inf)
        return self.options.cfl * p.comm.allreduce(local, op=MPI.MIN)

    def affine(self, check: bool = False) -> tuple[npt.NDArray, npt.NDArray | None] | None:
        """The particles' affine matrices (the field ``affine``, (n, d, d)) and APIC's spins (the
        field ``affine_spin``, (n, 1) in 2D, (n, 3) in 3D; None for TPIC and in 1D), zeros where
        the fields are new, where the transfer carries them; else None. ``check``: their shapes
        (collective; the choice of grid checks them, the step's passes read them).

        Raises:
            ValueError: With ``check``, a given field of another shape (on every rank).
        """
        transfer = self.options.velocity_transfer
        if not transfer.affine:
            return None
        p = self.particles
        d, n = p.gdim, len(p)
        k = affine.spin_width(d) if transfer.kind == 1 else 0
        f = p.fields
        C = f[AFFINE_FIELD] if AFFINE_FIELD in f else f.setdefault(AFFINE_FIELD, np.zeros((n, d, d)))
        spin = (f[SPIN_FIELD] if SPIN_FIELD in f else f.setdefault(SPIN_FIELD, np.zeros((n, k)))) if k else None
        if not check:
            return C, spin
        bad = [f"{name!r} has shape {np.shape(a)}; expected {shape}"
               for name, a, shape in ((AFFINE_FIELD, C, (n, d, d)), (SPIN_FIELD, spin, (n, k)))
               if a is not None and np.shape(a) != shape]
        bad = p.comm.allgather(bad)
        if any(bad):
            raise ValueError(f"the particle field {next(b for b in bad if b)[0]} (the transfer's affine state)")
        return C, spin

    def dof_coordinates(self) -> npt.NDArray:
        """The coordinates of the space's (block) dofs, owned and ghost, made once
        (:func:`fempm.transfer.affine.dof_coordinates`). Collective the first time."""
        if self._dof_coordinates is None:
            self._dof_coordinates = affine.dof_coordinates(self.V)
        return self._dof_coordinates

    def affine_spin(self) -> npt.NDArray | None:
        r"""The particles' spins :math:`s_p` the grid map carries (the angular momentum's affine
        part, :func:`fempm.transfer.affine.angular_momentum`): APIC's stored ones, TPIC's
        :math:`\epsilon : (C_p D_p)^T`; None for the other transfers and for the consistent mass,
        whose exact projection leaves the affine part out. Collective."""
        state = self.affine()
        if state is None or self.options.mass_model.matrix or self.particles.gdim == 1:
            return None
        C, spin = state
        if spin is not None:
            return spin
        p = self.particles
        basis = ParticleBasis(self.V, p, domain=self.options.particle_domain)
        return affine.spin_of(C @ affine.second_moments(basis, self.dof_coordinates(), p.x))

    def relocate_particles(self, left: npt.NDArray[np.bool_] | None = None) -> None:
        """Locate the moved particles (``left``: the only ones that may have left their cells),
        under the ``outside`` policy (:class:`fempm.stepping.outside.Outside`). Collective."""
        self.removal.relocate(self.particles, self.materials, left)
