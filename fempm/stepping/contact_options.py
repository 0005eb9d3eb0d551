"""The options of multi-velocity-field contact (:class:`Contact`), apart from the grid that
steps it (:class:`fempm.stepping.contact.ContactGrid`, which names it too)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Contact"]


@dataclass(frozen=True)
class Contact:
    """Multi-velocity-field contact between particle groups (see the module).

    Args:
        friction: The Coulomb coefficient between the groups.
        field: The particle field naming each particle's group (integers 0, 1, ...; default
            the material index ``body``).
        mass_cutoff: A node where a group has less than this fraction of the largest nodal
            mass gives that group no force update there.
        rigid: The groups that are rigid bodies of prescribed motion (their velocities stand).
        gap: A length: groups are in contact only where they touch, their nodal centres of mass
            within ``gap`` along the normal (None: wherever two groups share a node).

    Raises:
        ValueError: A gap not > 0, rigid groups that are not non-negative integers, a negative
            or non-finite friction, a cut-off outside [0, 1).
    """

    friction: float = 0.0
    field: str = "body"
    mass_cutoff: float = 1e-2
    rigid: tuple[int, ...] = ()
    gap: float | None = None

    def __post_init__(self):
        if self.gap is not None and not 0.0 < self.gap < np.inf:
            raise ValueError(f"Contact needs a finite gap > 0 or None (got {self.gap!r})")
        object.__setattr__(self, "rigid", tuple(self.rigid))
        if not all(isinstance(g, (int, np.integer)) and not isinstance(g, bool) and g >= 0 for g in self.rigid):
            raise ValueError(f"Contact needs rigid groups as non-negative integers (got {self.rigid!r})")
        if not 0.0 <= self.friction < np.inf:
            raise ValueError(f"Contact needs a finite friction coefficient >= 0 (got {self.friction})")
        if not 0.0 <= self.mass_cutoff < 1.0:
            raise ValueError(f"Contact needs 0 <= mass_cutoff < 1 (got {self.mass_cutoff})")
