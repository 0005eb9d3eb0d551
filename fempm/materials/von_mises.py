r"""Von Mises (J2) plasticity with linear isotropic hardening, hypoelastic (Jaumann rate,
:mod:`fempm.materials.hypoelastic`), plane strain in 2D.

Yield function :math:`f = q - (\sigma_y + H \bar\varepsilon_p)` with
:math:`q = \sqrt{\tfrac32 s : s}`, :math:`s = \sigma - \tfrac13 \mathrm{tr}\,\sigma\, I`.
Radial return: where the trial stress has :math:`f^{tr} > 0`,

.. math::
    \Delta\gamma = \frac{f^{tr}}{3\mu + H}, \qquad
    s = \Big(1 - \frac{3\mu\,\Delta\gamma}{q^{tr}}\Big) s^{tr}, \qquad
    \bar\varepsilon_p \leftarrow \bar\varepsilon_p + \Delta\gamma,

the pressure unchanged: the closest point of the yield surface to the trial stress in the
energy norm, on the surface exactly (:math:`q = \sigma_y + H \bar\varepsilon_p`). Internal
variables: ``eps_p`` (equivalent plastic strain) and, in 2D, ``sigma_zz``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from fempm.kernels.plasticity import split, von_mises_return
from fempm.materials.base import Internal
from fempm.materials.hypoelastic import SIGMA_ZZ, HypoelasticPlastic

__all__ = ["VonMises"]


@dataclass(frozen=True)
class VonMises(HypoelasticPlastic):
    """J2 plasticity with linear isotropic hardening, hypoelastic (see the module).

    Args:
        E: Young's modulus.
        nu: Poisson's ratio.
        yield_stress: The initial yield stress (inf: elastic, the hypoelastic law alone).
        hardening: The linear hardening modulus :math:`H`.
    """

    yield_stress: float = np.inf
    hardening: float = 0.0
    history: ClassVar[tuple[Internal, ...]] = (Internal("eps_p"), SIGMA_ZZ)

    def __post_init__(self):
        super().__post_init__()
        if not 0.0 < self.yield_stress <= np.inf:
            raise ValueError(f"VonMises needs yield_stress > 0 (got {self.yield_stress})")
        if not 0.0 <= self.hardening < np.inf:
            raise ValueError(f"VonMises needs a finite hardening >= 0 (got {self.hardening})")

    def yield_function(self, S: npt.NDArray, eps_p: npt.NDArray) -> npt.NDArray:
        """:math:`f` (n,) of (n, 3, 3) stresses."""
        return np.sqrt(1.5 * split(S)[2]) - (self.yield_stress + self.hardening * eps_p)

    def return_map(self, S: npt.NDArray, eps_p: npt.NDArray) -> tuple[npt.NDArray, npt.NDArray]:
        """(returned stresses, equivalent plastic strains) of trial (n, 3, 3) stresses
        (:func:`fempm.kernels.plasticity.von_mises_return`, compiled)."""
        return von_mises_return(S, eps_p, self.yield_stress, self.hardening, self.lame[1])

    def return_tangent(self, S: npt.NDArray, eps_p: npt.NDArray, d: int | None = None) -> npt.NDArray:
        r""":math:`\partial \sigma_{ij} / \partial \sigma^{tr}_{ab}` (n, 3, 3, 3, 3) of the radial
        return of trial stresses ``S``: the identity where elastic; where plastic, with
        :math:`\beta = 3\mu\Delta\gamma / q^{tr}` and :math:`k = \sigma_y + H \bar\varepsilon_p`,

        .. math::
            \tfrac13 \delta_{ij}\delta_{ab} + (1 - \beta)\big(\delta_{ia}\delta_{jb}
            - \tfrac13 \delta_{ij}\delta_{ab}\big)
            - \frac{3\mu}{3\mu + H} \frac{3 k}{2 (q^{tr})^3}\, s^{tr}_{ij} s^{tr}_{ab}

        (the algorithmic tangent: :math:`\beta` varies with :math:`q^{tr}`)."""
        mu = self.lame[1]
        H = self.hardening
        _, dev, ss = split(S)
        q = np.sqrt(1.5 * ss)
        k = self.yield_stress + H * eps_p
        plastic = q - k > 0
        qp = np.where(plastic, q, 1.0)
        beta = np.where(plastic, 3 * mu / (3 * mu + H) * (1.0 - k / qp), 0.0)
        c = np.where(plastic, 3 * mu / (3 * mu + H) * 1.5 * k / qp**3, 0.0)
        e = np.eye(3)
        iso = np.einsum("ij,ab->ijab", e, e) / 3.0
        unit = np.einsum("ia,jb->ijab", e, e)
        return (iso + (1.0 - beta)[:, None, None, None, None] * (unit - iso)
                - c[:, None, None, None, None] * np.einsum("nij,nab->nijab", dev, dev))

    def stress(self, F, L, sigma, dt, rho, state) -> npt.NDArray:
        S, state["eps_p"] = self.return_map(self.trial(L, sigma, dt, state), state["eps_p"])
        return self.finish(S, L.shape[1], state)
