r"""Update schemes: the order of the stages of an explicit step on a :class:`~fempm.stepping.grid.Grid`.

* :class:`USL` (update stress last): map, grid update, then G2P with the PIC/FLIP blend, the
  kinematics (:math:`L_p`, :math:`F_p`, the stress) and the motion in one particle pass;
* :class:`USF` (update stress first): the stress from the mapped velocity before the forces
  are mapped, then the grid update and the blend and motion;
* :class:`MUSL` (modified USL): the blend, the grid velocity re-mapped from the updated
  particle momenta, then the kinematics and the motion with that velocity.
"""

from __future__ import annotations

from typing import ClassVar, Protocol

import numpy.typing as npt

__all__ = ["MUSL", "SCHEMES", "USF", "USL", "Scheme", "Stages", "scheme"]


class Stages(Protocol):
    """The stages a scheme orders (:class:`fempm.stepping.grid.Grid` implements them)."""

    def velocity(self, remapped: bool = False) -> npt.NDArray:
        """The grid velocity of the mapped (or re-mapped) momenta."""

    def forces(self) -> None:
        """P2G of the internal and external forces."""

    def advance(self, v_old: npt.NDArray, dt: float) -> npt.NDArray:
        """The updated grid velocity."""

    def update(self, dt: float) -> tuple[npt.NDArray, npt.NDArray]:
        """(the grid velocity, the updated one): velocity and advance, maybe fused."""

    def to_particles(self, v_new: npt.NDArray, v_old: npt.NDArray, dt: float, *, blend: bool = False,
                     kinematics: bool = False, move: bool = False, remap: bool = False) -> npt.NDArray | None:
        """G2P: the blend, the kinematics, the motion, the re-map, as asked."""


class Scheme:
    """An ordering of the :class:`Stages` of a grid (:class:`~fempm.stepping.grid.Grid`).

    Attributes:
        name: the option's name.
        forces_with_map: whether the internal and external forces are mapped with the mass and
            momentum (in the same particle pass), before any particle is updated.
    """

    name: ClassVar[str] = ""
    forces_with_map: ClassVar[bool] = True

    def update(self, grid: Stages, dt: float) -> npt.NDArray:
        """The stages after the map and the time step; returns the grid velocity the particles
        moved with (owned + ghost dofs, d)."""
        raise NotImplementedError

    def __repr__(self) -> str:
        return self.name


class USL(Scheme):
    name = "USL"

    def update(self, grid: Stages, dt: float) -> npt.NDArray:
        v_old, v_new = grid.update(dt)
        grid.to_particles(v_new, v_old, dt, blend=True, kinematics=True, move=True)
        return v_new


class USF(Scheme):
    name = "USF"
    forces_with_map = False

    def update(self, grid: Stages, dt: float) -> npt.NDArray:
        v_old = grid.velocity()
        grid.to_particles(v_old, v_old, dt, kinematics=True)  # the stress from the mapped velocity
        grid.forces()
        v_new = grid.advance(v_old, dt)
        grid.to_particles(v_new, v_old, dt, blend=True, move=True)
        return v_new


class MUSL(Scheme):
    name = "MUSL"

    def update(self, grid: Stages, dt: float) -> npt.NDArray:
        v_old, v_new = grid.update(dt)
        grid.to_particles(v_new, v_old, dt, blend=True, remap=True)
        v_new = grid.velocity(remapped=True)
        grid.to_particles(v_new, v_new, dt, kinematics=True, move=True)
        return v_new


SCHEMES = {s.name: s for s in (USL, USF, MUSL)}


def scheme(name: str | Scheme) -> Scheme:
    """The scheme of an option (a :class:`Scheme` or its name)."""
    if isinstance(name, Scheme):
        return name
    if name not in SCHEMES:
        raise ValueError(f"unknown option scheme={name!r}; expected USL, USF or MUSL")
    return SCHEMES[name]()
