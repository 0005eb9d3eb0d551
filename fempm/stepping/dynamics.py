r"""The time integration of an implicit step: Newmark's method or quasi-static equilibrium.

With the grid's displacement increment :math:`\Delta u` over a step :math:`\Delta t`, and the grid
velocity :math:`v` and acceleration :math:`a` at the step's start, Newmark's method
(:class:`Newmark`) takes

.. math::
    a^{+} = \frac{\Delta u - \Delta t\, v - \Delta t^2 (\tfrac12 - \beta)\, a}{\beta \Delta t^2},
    \qquad v^{+} = v + \Delta t\, \big((1 - \gamma)\, a + \gamma\, a^{+}\big),

so the inertia :math:`M a^{+}` adds :math:`M / (\beta \Delta t^2)` to the tangent; with
:math:`\beta = 1/4`, :math:`\gamma = 1/2` (the trapezoidal rule, the default) it is unconditionally
stable and conserves the energy of a linear system. :class:`QuasiStatic` drops the inertia: each
step is an equilibrium under the loads of its end time.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy.typing as npt

__all__ = ["DYNAMICS", "Newmark", "QuasiStatic", "time_integration"]

#: the names ``StepOptions(dynamics=...)`` takes
DYNAMICS = ("newmark", "quasi-static")


@dataclass(frozen=True)
class Newmark:
    """Newmark's method with parameters ``beta`` in (0, 1/2] and ``gamma`` >= 1/2 (see the module)."""

    beta: float = 0.25
    gamma: float = 0.5
    inertia: ClassVar[bool] = True
    name: ClassVar[str] = "newmark"

    def __post_init__(self):
        if not 0.0 < self.beta <= 0.5:
            raise ValueError(f"newmark_beta={self.beta} must lie in (0, 1/2]")
        if not 0.5 <= self.gamma <= 1.0:
            raise ValueError(f"newmark_gamma={self.gamma} must lie in [1/2, 1] (below 1/2 Newmark's method is "
                             "unstable)")

    def mass_factor(self, dt: float) -> float:
        r""":math:`1 / (\beta \Delta t^2)`: the inertia's share of the tangent per unit mass."""
        return 1.0 / (self.beta * dt * dt)

    def acceleration(self, du: npt.NDArray, v: npt.NDArray, a: npt.NDArray, dt: float) -> npt.NDArray:
        r""":math:`a^{+}` of the increment ``du`` from the step's start ``v``, ``a``."""
        return (du - dt * v - (dt * dt * (0.5 - self.beta)) * a) / (self.beta * dt * dt)

    def velocity(self, v: npt.NDArray, a: npt.NDArray, a_new: npt.NDArray, dt: float) -> npt.NDArray:
        r""":math:`v^{+} = v + \Delta t ((1 - \gamma) a + \gamma a^{+})`."""
        return v + dt * ((1.0 - self.gamma) * a + self.gamma * a_new)


@dataclass(frozen=True)
class QuasiStatic:
    """Equilibrium at each step's end, no inertia (see the module)."""

    inertia: ClassVar[bool] = False
    name: ClassVar[str] = "quasi-static"

    def mass_factor(self, dt: float) -> float:
        return 0.0


def time_integration(dynamics: str, beta: float = 0.25, gamma: float = 0.5) -> Newmark | QuasiStatic:
    """The time integration named ``dynamics`` (one of :data:`DYNAMICS`).

    Raises:
        ValueError: An unknown name, or Newmark parameters out of range.
    """
    if dynamics == "newmark":
        return Newmark(beta, gamma)
    if dynamics == "quasi-static":
        return QuasiStatic()
    raise ValueError(f"unknown option dynamics={dynamics!r}; expected one of {', '.join(DYNAMICS)}")
