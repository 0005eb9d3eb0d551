r"""Compressible neo-Hookean solid:
:math:`\sigma = \frac{\mu}{J}(F F^T - I) + \frac{\lambda \ln J}{J} I`,
stored energy :math:`W = \frac{\mu}{2}(\mathrm{tr}\, F^T F - d) - \mu \ln J + \frac{\lambda}{2} (\ln J)^2`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from fempm.kernels.kinematics import elastic_energy, neo_hookean_stress
from fempm.kernels.particle_checks import NEO_HOOKEAN
from fempm.materials.base import IsotropicElastic, identity

__all__ = ["NeoHookean"]


@dataclass(frozen=True)
class NeoHookean(IsotropicElastic):
    """The compressible neo-Hookean solid (see the module).

    Args:
        E: Young's modulus (of the linearised law).
        nu: Poisson's ratio, in (-1, 0.5).
    """

    nu: float = 0.3

    def stress(self, F, L, sigma, dt, rho) -> npt.NDArray:
        """The compiled kernel :func:`fempm.kernels.neo_hookean_stress`; :meth:`stress_numpy`
        is its reference."""

        return neo_hookean_stress(np.ascontiguousarray(F), *self.lame)

    def stress_numpy(self, F, L, sigma, dt, rho) -> npt.NDArray:
        lam, mu = self.lame
        J = np.linalg.det(F)
        B = F @ np.swapaxes(F, 1, 2)
        d = F.shape[1]
        return (mu * (B - identity(len(F), d)) + (lam * np.log(J))[:, None, None] * identity(len(F), d)) / J[:, None, None]

    def tangent(self, F, G, sigma=None, state=None) -> npt.NDArray:
        r""":math:`\partial \sigma_{ij} / \partial G_{kl}` (n, d, d, d, d) of the increment
        :math:`F = \Delta F\, F_n`, :math:`\Delta F = I + G` (:mod:`fempm.materials.tangent`),
        with :math:`J = \det F`, :math:`B = F F^T`:

        .. math::
            \Big(\frac{\lambda (1 - \ln J)}{J} \delta_{ij} - \frac{\mu}{J} (B - I)_{ij}\Big) \Delta F^{-1}_{lk}
            + \frac{\mu}{J} \big(\delta_{ik} (F F_n^T)_{jl} + \delta_{jk} (F F_n^T)_{il}\big).
        """
        lam, mu = self.lame
        d = F.shape[1]
        eye = np.eye(d)
        Fnew = F + G @ F
        J = np.linalg.det(Fnew)
        B = Fnew @ np.swapaxes(Fnew, 1, 2)
        volumetric = ((lam * (1.0 - np.log(J)) / J)[:, None, None] * eye - (mu / J)[:, None, None] * (B - eye))
        FFn = Fnew @ np.swapaxes(F, 1, 2)
        dFinv = np.linalg.inv(eye + G)
        return (np.einsum("nij,nlk->nijkl", volumetric, dFinv)
                + (mu / J)[:, None, None, None, None] * (np.einsum("ik,njl->nijkl", eye, FFn)
                                                           + np.einsum("jk,nil->nijkl", eye, FFn)))

    def energy_density(self, F) -> npt.NDArray:
        """The stored energy per reference volume (n,), compiled
        (:func:`fempm.kernels.kinematics.elastic_energy`, its numpy reference ``elastic_energy_numpy``)."""
        return elastic_energy(NEO_HOOKEAN, F, *self.lame)
