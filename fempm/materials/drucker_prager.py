r"""Drucker-Prager plasticity, non-associated, perfectly plastic, with a tension cut-off;
hypoelastic (Jaumann rate, :mod:`fempm.materials.hypoelastic`), plane strain in 2D.

Yield function and plastic potential, with :math:`p = \tfrac13 \mathrm{tr}\,\sigma` (tension
positive) and :math:`J_2 = \tfrac12 s : s`:

.. math::
    f = \sqrt{J_2} + \eta\, p - \xi c, \qquad g = \sqrt{J_2} + \bar\eta\, p .

The cone is matched to Mohr-Coulomb with friction angle :math:`\phi`, dilation angle
:math:`\psi \le \phi` and cohesion :math:`c`.

In 2D (plane strain) the match is that of steady plane-strain plastic flow (no out-of-plane
plastic strain rate, :math:`\partial g / \partial \sigma_{zz} = 0`): there the in-plane
principal stresses satisfy Mohr-Coulomb,
:math:`\tfrac12(\sigma_1 - \sigma_2) = c\cos\phi - \tfrac12(\sigma_1 + \sigma_2)\sin\phi`, and the
in-plane plastic strain rates have the dilatancy of :math:`\psi`,
:math:`\sin\psi = -(\dot\epsilon_1 + \dot\epsilon_2)/(\dot\epsilon_1 - \dot\epsilon_2)`, when

.. math::
    \bar\eta = \frac{\sqrt3 \sin\psi}{\sqrt{3 + \sin^2\psi}}, \qquad
    \eta = \frac{3 \sin\phi}{\sqrt3 \sqrt{3 - \bar\eta^2} + \bar\eta \sin\phi}, \qquad
    \xi = \frac{(3 - \eta\bar\eta) \cos\phi}{\sqrt3 \sqrt{3 - \bar\eta^2}}

(in steady plane-strain flow :math:`s_{zz} = -\tfrac23 \bar\eta \sqrt{J_2}`, so that
:math:`\sqrt{J_2} = \sqrt3\, t / \sqrt{3 - \bar\eta^2}` and
:math:`p = \tfrac12(\sigma_1 + \sigma_2) - \bar\eta\, t / (\sqrt3 \sqrt{3 - \bar\eta^2})` with
:math:`t = \tfrac12(\sigma_1 - \sigma_2)`; putting them into :math:`f = 0` gives Mohr-Coulomb).
For associated flow (:math:`\psi = \phi`) this is the classical plane-strain match
:math:`\eta = 3\tan\phi / \sqrt{9 + 12\tan^2\phi}`, :math:`\xi = 3 / \sqrt{9 + 12\tan^2\phi}`
(de Souza Neto, Peric and Owen, *Computational Methods for Plasticity*, 2008, section 8.2.1);
for :math:`\psi = 0` it is :math:`\eta = \sin\phi`, :math:`\xi = \cos\phi`. (The classical
match used with :math:`\psi = 0` mobilises only 28.7 degrees for :math:`\phi` = 30 and 37.1 for
40 in steady flow.)

In 3D the cone passes through the outer edges of Mohr-Coulomb (triaxial compression),
:math:`\eta = 6\sin\phi / (\sqrt3 (3 - \sin\phi))`, :math:`\xi = 6\cos\phi / (\sqrt3 (3 - \sin\phi))`,
:math:`\bar\eta` likewise from :math:`\psi`.

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

from fempm.kernels.plasticity import drucker_prager_return, split
from fempm.materials.base import Internal
from fempm.materials.hypoelastic import SIGMA_ZZ, HypoelasticPlastic

__all__ = ["DruckerPrager", "cone", "plane_strain_cone"]


def cone(angle_deg: float, d: int) -> tuple[float, float]:
    """(eta, xi) of the Mohr-Coulomb match of associated flow for an angle in degrees: plane
    strain in 2D, the outer cone in 3D (the eta of a dilation angle is its eta_bar)."""
    a = np.radians(angle_deg)
    if d == 2:
        root = np.sqrt(9.0 + 12.0 * np.tan(a) ** 2)
        return 3.0 * np.tan(a) / root, 3.0 / root
    return 6.0 * np.sin(a) / (np.sqrt(3.0) * (3.0 - np.sin(a))), 6.0 * np.cos(a) / (np.sqrt(3.0) * (3.0 - np.sin(a)))


def plane_strain_cone(friction_deg: float, dilation_deg: float) -> tuple[float, float, float]:
    """(eta, xi, eta_bar) of the match to Mohr-Coulomb in steady plane-strain flow with the
    dilation angle (see the module); the classical match for associated flow."""
    phi = np.radians(friction_deg)
    eta_bar = cone(dilation_deg, 2)[0]
    root = np.sqrt(3.0) * np.sqrt(3.0 - eta_bar**2)
    eta = 3.0 * np.sin(phi) / (root + eta_bar * np.sin(phi))
    return eta, (3.0 - eta * eta_bar) * np.cos(phi) / root, eta_bar


@dataclass(frozen=True)
class DruckerPrager(HypoelasticPlastic):
    r"""Drucker-Prager plasticity matched to Mohr-Coulomb, non-associated, with a tension cut-off
    (see the module).

    Args:
        E: Young's modulus.
        nu: Poisson's ratio.
        friction_angle: :math:`\phi` in degrees, in [0, 90).
        dilation_angle: :math:`\psi` in degrees, in [0, :math:`\phi`].
        cohesion: :math:`c` >= 0.
        tension: The tension cut-off on the mean stress (None: the cone's apex).
    """

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
        if d == 2:
            eta, xi, eta_bar = plane_strain_cone(self.friction_angle, self.dilation_angle)
        else:
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

    def return_tangent(self, S: npt.NDArray, eps_p: npt.NDArray, d: int) -> npt.NDArray:
        r""":math:`\partial \sigma_{ij} / \partial \sigma^{tr}_{ab}` (n, 3, 3, 3, 3) of the return
        mapping of trial stresses ``S`` in ``d`` dimensions (the algorithmic tangent). On the
        cone, with :math:`r = \sqrt{J_2^{tr}}`, :math:`\Delta\gamma = f^{tr} / (G + K \eta\bar\eta)`,
        :math:`s = (1 - G\Delta\gamma / r)\, s^{tr}`, :math:`p = p^{tr} - K\bar\eta\,\Delta\gamma`:
        the derivatives of these through :math:`\partial r / \partial \sigma^{tr} = s^{tr} / (2 r)`
        and :math:`\partial p^{tr} / \partial \sigma^{tr} = I / 3`. At the apex the stress is
        fixed (a zero tangent: the stress no longer depends on the strain; a step with every
        particle at the apex has no stiffness but the inertia's). Where the tension cut-off
        holds the mean stress, its row of the derivative is zero."""
        lam, G = self.lame
        K = lam + 2 * G / 3
        eta, k, eta_bar, p_t = self.parameters(d)
        p, dev, ss = split(S)
        root = np.sqrt(0.5 * ss)
        f = root + eta * p - k
        den = G + K * eta * eta_bar
        dgamma = np.where(f > 0, f, 0.0) / den
        apex = (f > 0) & (root - G * dgamma < 0)
        cone_ = (f > 0) & ~apex
        r = np.where(cone_, root, 1.0)
        e = np.eye(3)
        iso = np.einsum("ij,ab->ijab", e, e) / 3.0
        ddev = np.einsum("ia,jb->ijab", e, e) - iso  # d s_ij / d S_ab
        dp = np.broadcast_to(e / 3.0, S.shape)
        droot = np.where(cone_[:, None, None], dev / (2.0 * r[:, None, None]), 0.0)
        ddg = (droot + eta * dp) / den
        scale = np.where(cone_, (root - G * dgamma) / r, 1.0)
        dscale = np.where(cone_[:, None, None], (droot - G * ddg - scale[:, None, None] * droot) / r[:, None, None],
                          0.0)
        dp_new = np.where(cone_[:, None, None], dp - K * eta_bar * ddg, dp)
        p_new = np.where(cone_, p - K * eta_bar * dgamma, p)
        if eta > 0:  # the apex: the stress is the apex point
            p_new[apex] = k / eta
            dp_new = np.where(apex[:, None, None], 0.0, dp_new)
        dp_new = np.where((p_new > p_t)[:, None, None], 0.0, dp_new)  # held by the tension cut-off
        R = (np.einsum("nij,nab->nijab", dev, dscale) + scale[:, None, None, None, None] * ddev
             + np.einsum("ij,nab->nijab", e, dp_new))
        R[apex] = np.einsum("ij,nab->nijab", e, dp_new[apex])
        return R

    def stress(self, F, L, sigma, dt, rho, state) -> npt.NDArray:
        d = L.shape[1]
        S, state["eps_p"] = self.return_map(self.trial(L, sigma, dt, state), state["eps_p"], d)
        return self.finish(S, d, state)
