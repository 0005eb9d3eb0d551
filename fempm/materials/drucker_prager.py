r"""Drucker-Prager plasticity, non-associated, perfectly plastic, with a tension cut-off;
hypoelastic (Jaumann rate, :mod:`fempm.materials.hypoelastic`), plane strain in 2D.

Yield function and plastic potential, with :math:`p = \tfrac13 \mathrm{tr}\,\sigma` (tension
positive) and :math:`J_2 = \tfrac12 s : s`:

.. math::
    f = \sqrt{J_2} + \eta\, p - \xi c, \qquad g = \sqrt{J_2} + \bar\eta\, p .

The cone is matched to Mohr-Coulomb with friction angle :math:`\phi` and cohesion :math:`c`
(de Souza Neto, Peric and Owen, *Computational Methods for Plasticity*, 2008, section 8.2.1):
in 2D to the plane-strain failure load,
:math:`\eta = 3\tan\phi / \sqrt{9 + 12\tan^2\phi}`, :math:`\xi = 3 / \sqrt{9 + 12\tan^2\phi}`;
in 3D to the outer edges (triaxial compression),
:math:`\eta = 6\sin\phi / (\sqrt3 (3 - \sin\phi))`, :math:`\xi = 6\cos\phi / (\sqrt3 (3 - \sin\phi))`;
:math:`\bar\eta` likewise from the dilation angle :math:`\psi \le \phi`.

Return mapping (exact for this cone, elastic moduli :math:`G = \mu`, :math:`K`): where
:math:`f^{tr} > 0`, :math:`\Delta\gamma = f^{tr} / (G + K \eta\bar\eta)`,
:math:`\sqrt{J_2} = \sqrt{J_2^{tr}} - G\Delta\gamma`, :math:`p = p^{tr} - K\bar\eta\,\Delta\gamma`,
the deviator scaled; where that passes the apex (:math:`\sqrt{J_2} < 0`), the stress goes to
the apex :math:`p = \xi c/\eta`, :math:`s = 0`. Then the tension cut-off :math:`p \le p_t`
(``tension``, default the apex) returns along the hydrostatic axis. Cohesionless sand
(:math:`c = 0`) carries no tension. Internal variables: ``eps_p`` (the equivalent deviatoric
plastic strain, :math:`\Delta\gamma/\sqrt3` a step) and, in 2D, ``sigma_zz``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from fempm.kernels.plasticity import drucker_prager_return
from fempm.materials.base import Internal
from fempm.materials.hypoelastic import SIGMA_ZZ, HypoelasticPlastic, split


def cone(angle_deg: float, d: int) -> tuple[float, float]:
    """(eta, xi) of the Mohr-Coulomb match for an angle in degrees: plane strain in 2D, the
    outer cone in 3D."""
    a = np.radians(angle_deg)
    if d == 2:
        root = np.sqrt(9.0 + 12.0 * np.tan(a) ** 2)
        return 3.0 * np.tan(a) / root, 3.0 / root
    return 6.0 * np.sin(a) / (np.sqrt(3.0) * (3.0 - np.sin(a))), 6.0 * np.cos(a) / (np.sqrt(3.0) * (3.0 - np.sin(a)))


@dataclass(frozen=True)
class DruckerPrager(HypoelasticPlastic):
    """``DruckerPrager(E, nu, friction_angle, dilation_angle=0.0, cohesion=0.0, tension=None)``,
    angles in degrees (see the module)."""

    friction_angle: float = 30.0
    dilation_angle: float = 0.0
    cohesion: float = 0.0
    tension: float | None = None
    history: ClassVar[tuple[Internal, ...]] = (Internal("eps_p"), SIGMA_ZZ)

    def __post_init__(self):
        super().__post_init__()
        if not 0.0 <= self.friction_angle < 90.0:
            raise ValueError(f"DruckerPrager needs 0 <= friction_angle < 90 degrees (got {self.friction_angle})")
        if not 0.0 <= self.dilation_angle <= self.friction_angle:
            raise ValueError(f"DruckerPrager needs 0 <= dilation_angle <= friction_angle (got {self.dilation_angle})")
        if not 0.0 <= self.cohesion < np.inf:
            raise ValueError(f"DruckerPrager needs a finite cohesion >= 0 (got {self.cohesion})")
        if self.friction_angle == 0.0 and self.cohesion == 0.0:
            raise ValueError("DruckerPrager needs a friction angle or a cohesion (both 0: no strength)")
        if self.tension is not None and not self.tension >= 0.0:
            raise ValueError(f"DruckerPrager needs tension >= 0 (got {self.tension})")

    def parameters(self, d: int) -> tuple[float, float, float, float]:
        """(eta, xi c, eta_bar, p_t) in ``d`` dimensions."""
        eta, xi = cone(self.friction_angle, d)
        eta_bar = cone(self.dilation_angle, d)[0]
        apex = xi * self.cohesion / eta if eta > 0 else np.inf
        return eta, xi * self.cohesion, eta_bar, min(apex, np.inf if self.tension is None else self.tension)

    def yield_function(self, S: npt.NDArray, d: int) -> npt.NDArray:
        """:math:`f` (n,) of (n, 3, 3) stresses."""
        eta, k, _, _ = self.parameters(d)
        p, _, ss = split(S)
        return np.sqrt(0.5 * ss) + eta * p - k

    def return_map(self, S: npt.NDArray, eps_p: npt.NDArray, d: int) -> tuple[npt.NDArray, npt.NDArray]:
        """(returned stresses, equivalent plastic strains) of trial (n, 3, 3) stresses
        (:func:`fempm.kernels.plasticity.drucker_prager_return`, compiled)."""
        lam, G = self.lame
        return drucker_prager_return(S, eps_p, *self.parameters(d), G, lam + 2 * G / 3)

    def stress(self, F, L, sigma, dt, rho, state) -> npt.NDArray:
        d = L.shape[1]
        S, state["eps_p"] = self.return_map(self.trial(L, sigma, dt, state), state["eps_p"], d)
        return self.finish(S, d, state)
