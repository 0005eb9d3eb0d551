r"""Weakly compressible Newtonian fluid with the Tait equation of state:
:math:`p = \kappa\left((\rho/\rho_0)^\gamma - 1\right)`,
:math:`\sigma = -p I + 2\eta\, \mathrm{dev}\, D`, :math:`D = \mathrm{sym}\, L`,
sound speed :math:`c = \sqrt{\kappa\gamma/\rho_0\, (\rho/\rho_0)^{\gamma - 1}}`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from fempm.arguments import check_numbers
from fempm.kernels.kinematics import sym
from fempm.materials.base import identity, trace

__all__ = ["NewtonianTait"]


@dataclass(frozen=True)
class NewtonianTait:
    """A weakly compressible Newtonian fluid with the Tait equation of state (see the module).

    Args:
        rho0: The reference density.
        kappa: The bulk stiffness of the equation of state.
        gamma: The Tait exponent.
        viscosity: The dynamic viscosity.
        history: The internal variables (none).
    """

    rho0: float
    kappa: float = 2.0e4
    gamma: float = 7.0
    viscosity: float = 1.0e-3
    history: tuple = ()
    #: the law takes F-bar's averaged deformation (fempm.stepping.fbar): its pressure from the
    #: density, which follows the averaged volume, its viscous stress from L
    volumetric_average: ClassVar[bool] = True

    def __post_init__(self):
        check_numbers(self)
        for name, low in (("rho0", 0.0), ("kappa", 0.0), ("gamma", 1.0)):
            value = getattr(self, name)
            if not (low < value < np.inf):
                raise ValueError(f"NewtonianTait needs {name} > {low:g} and finite (got {name}={value})")
        if not (0.0 <= self.viscosity < np.inf):
            raise ValueError(f"NewtonianTait needs a finite viscosity >= 0 (got viscosity={self.viscosity})")

    def pressure(self, rho: npt.NDArray) -> npt.NDArray:
        return self.kappa * ((rho / self.rho0) ** self.gamma - 1.0)

    def stress(self, F, L, sigma, dt, rho) -> npt.NDArray:
        d = L.shape[1]
        D = sym(L)
        dev = D - (trace(D) / d)[:, None, None] * identity(len(L), d)
        return -self.pressure(rho)[:, None, None] * identity(len(L), d) + 2 * self.viscosity * dev

    def wave_speed(self, F, rho) -> npt.NDArray:
        return np.sqrt(self.kappa * self.gamma / self.rho0 * (rho / self.rho0) ** (self.gamma - 1))

    def energy_density(self, F) -> npt.NDArray:
        J = np.linalg.det(F)
        g = self.gamma  # W(J) with dW/dJ = -p(J): kappa (J^(1-g)/(g-1) + J) - kappa g/(g-1)
        return self.kappa * (J ** (1 - g) / (g - 1) + J - g / (g - 1))
