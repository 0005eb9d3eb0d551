"""What the parts of a step read and update of the solver's state: :class:`StepState`.

The grids (:mod:`fempm.stepping.grid` and the compiled ones), the particle stages, the choice of
grid and the implicit step take the solver as a :class:`StepState`: its space, particles, laws,
loads, options and conditions, the step's record and time, and the checks and hooks they call
(failing collectively, relocating the particles). This module imports none of them, so that
their annotations close no import cycle (``tests/architecture/test_imports.py``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import dolfinx.fem
import numpy.typing as npt

from fempm.boundary.conditions import GridConditions
from fempm.colliders.grid import ColliderContact
from fempm.particles.particle_set import Particles
from fempm.stepping.contact_options import Contact
from fempm.stepping.loads import Loads
from fempm.stepping.options import StepOptions
from fempm.stepping.outside import Outside
from fempm.stepping.record import StepRecord

__all__ = ["StepState"]


class StepState(Protocol):
    """The solver as a step's parts see it (:class:`fempm.stepping.ExplicitSolver` is one).

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
    t: float
    grid_velocity: npt.NDArray | None

    def fail(self, what: str) -> None:
        """Stop the step on every rank with ``what`` (a :class:`~fempm.stepping.SimulationError`)."""

    def check_state(self) -> None:
        """The particles' state checks that open a step (collective)."""

    def check_finite(self) -> None:
        """The finite-state check that closes a step (collective)."""

    def count_terms(self) -> None:
        """Count the force terms the step assembles (the record's ``terms``)."""

    def relocate_particles(self) -> None:
        """Locate and migrate the moved particles, removing or refusing those outside (collective)."""

    def particle_ids(self, mask: npt.NDArray) -> str:
        """The ids of the particles of ``mask`` (a few, over every rank), for messages."""

    def stable_dt(self) -> float:
        """The stable time step of the state now (collective)."""
