"""The vibrating bar: the exact small-strain solution of an elastic bar's first mode."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from fempm.materials.linear_elastic import LinearElastic
from fempm.verification.problem import Problem, as_columns

__all__ = ["VibratingBar", "vibrating_bar"]


@dataclass(frozen=True)
class VibratingBar(Problem):
    r"""First mode of a bar fixed at :math:`X = 0` and free at :math:`X = L`
    (docs/verification.md):

    .. math::
        u = \frac{v_0}{\omega} \sin(\beta X) \sin(\omega t), \qquad
        \beta = \frac{(2n - 1)\pi}{2L}, \qquad \omega = \beta \sqrt{E/\rho_0}.

    With :math:`P = \sigma = E (F - 1)` (:class:`LinearElastic`, :math:`\nu = 0`) the bar
    equation :math:`\rho_0 \ddot u = E u_{,XX}` is linear and :math:`u` solves it exactly:
    :math:`b = 0`. The background reaches 4 cells past the free end.
    """

    L: float = 25.0
    E: float = 100.0
    rho0: float = 1.0
    v0: float = 0.1
    mode: int = 1
    t_end: float = 10.0  # one period for the default parameters

    def __post_init__(self):
        self.declare(name="vibrating_bar", has_body_force=False)

    @property
    def material(self) -> LinearElastic:
        return LinearElastic(self.E, 0.0)

    @property
    def beta(self) -> float:
        return (2 * self.mode - 1) * np.pi / (2 * self.L)

    @property
    def omega(self) -> float:
        return self.beta * float(np.sqrt(self.E / self.rho0))

    @property
    def upper(self):
        return (self.L,)

    def background(self, h: float):
        return (0.0,), (self.L + 4 * h,)

    def displacement(self, X, t: float) -> npt.NDArray:
        X = as_columns(X, 1)
        return self.v0 / self.omega * np.sin(self.beta * X) * np.sin(self.omega * t)

    def velocity(self, X, t: float) -> npt.NDArray:
        X = as_columns(X, 1)
        return self.v0 * np.sin(self.beta * X) * np.cos(self.omega * t)

    def deformation_gradient(self, X, t: float) -> npt.NDArray:
        X = as_columns(X, 1)
        return (1.0 + self.v0 / self.omega * self.beta * np.cos(self.beta * X) * np.sin(self.omega * t))[:, :, None]

    def body_force(self, X, t: float) -> npt.NDArray:
        return np.zeros_like(as_columns(X, 1))

    def walls(self):
        return [(0, 0.0, "fixed")]


def vibrating_bar(**kwargs) -> VibratingBar:
    """Vibrating bar (L = 25, E = 100, rho0 = 1, v0 = 0.1, first mode) as an exact solution."""
    return VibratingBar(**kwargs)
