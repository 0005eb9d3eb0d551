r"""Linear elasticity, small strain: :math:`\sigma = \lambda\, \mathrm{tr}\,\varepsilon\, I + 2\mu
\varepsilon` with :math:`\varepsilon = \mathrm{sym}(F) - I`.

In 1D with :math:`\nu = 0` this is :math:`\sigma = E (F - 1)`, for which the Lagrangian bar
equation is exactly linear (the vibrating-bar reference).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from fempm.kernels.implicit import linear_elastic_tangent
from fempm.kernels.kinematics import elastic_energy, linear_elastic_stress, sym
from fempm.kernels.particle_checks import LINEAR_ELASTIC
from fempm.materials.base import IsotropicElastic, identity, trace

__all__ = ["LinearElastic"]


@dataclass(frozen=True)
class LinearElastic(IsotropicElastic):
    r"""Linear elasticity, small strain (see the module). Its volumetric strain is
    :math:`\mathrm{tr}\,F - d`, which F-bar averages for it (``volumetric_measure``,
    :mod:`fempm.stepping.fbar`).

    Args:
        E: Young's modulus.
        nu: Poisson's ratio, in (-1, 0.5).
    """

    #: what F-bar averages for this law (fempm.stepping.fbar): tr F - d, its volumetric strain
    volumetric_measure: ClassVar[str] = "trace"
    #: its tangent depends on F_n alone, not on the increment (fempm.materials.tangent.tangent_fixed_in_step)
    tangent_fixed_in_step: ClassVar[bool] = True

    def strain(self, F: npt.NDArray) -> npt.NDArray:
        return sym(F) - identity(len(F), F.shape[1])

    def stress(self, F, L, sigma, dt, rho) -> npt.NDArray:
        """The compiled kernel :func:`fempm.kernels.linear_elastic_stress`; :meth:`stress_numpy`
        is its reference."""

        return linear_elastic_stress(np.ascontiguousarray(F), *self.lame)

    def stress_numpy(self, F, L, sigma, dt, rho) -> npt.NDArray:
        lam, mu = self.lame
        eps = self.strain(F)
        return lam * trace(eps)[:, None, None] * identity(len(F), F.shape[1]) + 2 * mu * eps

    def tangent(self, F, G, sigma=None, state=None) -> npt.NDArray:
        r""":math:`\partial \sigma_{ij} / \partial G_{kl}` (n, d, d, d, d) of the increment
        :math:`F = (I + G) F_n` (:mod:`fempm.materials.tangent`):
        :math:`\lambda\, \delta_{ij} F_{n,lk} + \mu (\delta_{ik} F_{n,lj} + \delta_{jk} F_{n,li})`,
        independent of ``G`` (the law is linear in F); compiled
        (:func:`fempm.kernels.implicit.linear_elastic_tangent`)."""
        return linear_elastic_tangent(F, *self.lame)

    def energy_density(self, F) -> npt.NDArray:
        """The stored energy per reference volume (n,), compiled
        (:func:`fempm.kernels.kinematics.elastic_energy`, its numpy reference ``elastic_energy_numpy``)."""
        return elastic_energy(LINEAR_ELASTIC, F, *self.lame)
