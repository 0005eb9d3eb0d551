r"""Particles that leave the mesh (``ExplicitSolver(outside=...)``, ``Scene(outside=...)``,
``--outside``): :class:`Outside`.

* ``"raise"`` (the default): a particle found in no cell of any rank ends the run with an
  :class:`fempm.particles.location.OutsideMeshError` naming where it went (exit code 3 and a
  summary from the command line).
* ``"remove"``: such particles are dropped on every rank, and what they take with them is
  accounted: their count, mass, momentum, kinetic and strain energy (:class:`Removed`), as the
  difference of the global totals before and after the relocation that dropped them (the
  totals are invariant under migration between ranks, so what remains is what left, to
  round-off). A run's ``energies.csv`` then has the columns ``removed_mass``,
  ``removed_kinetic`` and ``removed_strain`` (running totals), ``summary.json`` the entry
  ``removed``, and the energy check counts the removed energy as having left
  (:class:`fempm.stepping.health.HealthMonitor`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from fempm.particles.particle_set import Particles
from fempm.stepping.diagnostics import totals

__all__ = ["OUTSIDE", "Outside", "Removed", "outside_policy"]

#: the policies ``outside=`` takes
OUTSIDE = ("raise", "remove")


@dataclass
class Removed:
    """What the removed particles took with them, summed over ranks and over the run."""

    count: int = 0
    mass: float = 0.0
    kinetic: float = 0.0
    strain: float = 0.0
    momentum: list[float] = field(default_factory=list)

    def asdict(self) -> dict:
        return {"count": self.count, "mass": self.mass, "kinetic": self.kinetic, "strain": self.strain,
                "momentum": list(self.momentum)}

    def columns(self) -> dict[str, float]:
        """The ``energies.csv`` columns (running totals)."""
        return {"removed_mass": self.mass, "removed_kinetic": self.kinetic, "removed_strain": self.strain}


def outside_policy(name: str) -> str:
    """``name`` checked against :data:`OUTSIDE`.

    Raises:
        ValueError: Another name.
    """
    if name not in OUTSIDE:
        raise ValueError(f"unknown option outside={name!r}; expected one of {', '.join(OUTSIDE)}")
    return name


class Outside:
    """The policy ``name`` (:data:`OUTSIDE`) for the particles that leave the mesh, and what the
    removed ones took (:attr:`removed`; see the module)."""

    def __init__(self, name: str = "raise"):
        #: whether particles found in no cell are removed (else they raise)
        self.removes = outside_policy(name) == "remove"
        self.removed = Removed()
        #: the mass and momentum the last relocation removed, None when it removed none (the
        #: energy check's work over the step in which they left counts them at its end)
        self.last_mass, self.last_momentum = 0.0, None

    def state_dict(self) -> dict:
        """What a continued run needs: what the removed particles took (:class:`Removed`)."""
        return self.removed.asdict()

    def load_state_dict(self, state: dict) -> None:
        """Restore :meth:`state_dict`."""
        self.removed = Removed(**state)

    @property
    def removed_now(self) -> bool:
        """Whether the last relocation removed particles."""
        return self.last_momentum is not None

    def columns(self) -> dict[str, float]:
        """The ``energies.csv`` columns of the removed particles (none unless removing)."""
        return self.removed.columns() if self.removes else {}

    def summary(self) -> dict:
        """The ``summary.json`` entry ``removed`` (none unless removing)."""
        return {"removed": self.removed.asdict()} if self.removes else {}

    def relocate(self, particles: Particles, materials: Sequence, left: npt.NDArray[np.bool_] | None = None) -> None:
        """Relocate ``particles`` (:meth:`fempm.particles.particle_set.Particles.relocate`, ``left``
        as there) under the policy, accounting the removed ones. Collective."""
        if not self.removes:
            particles.relocate(left=left)
            return
        before = totals(particles, materials)
        particles.relocate("remove", left=left)
        self.last_mass, self.last_momentum = 0.0, None
        if particles.removed:
            gone = before - totals(particles, materials)  # [mass, kinetic, strain, momentum...]
            self.last_mass, self.last_momentum = float(gone[0]), gone[3:].copy()
            r = self.removed
            r.count += int(particles.removed)
            r.mass += float(gone[0])
            r.kinetic += float(gone[1])
            r.strain += float(gone[2])
            r.momentum = [float(m) for m in np.asarray(r.momentum or np.zeros(len(gone) - 3)) + gone[3:]]
