r"""The local :math:`\mu(I)` rheology of dense granular flow (Jop, Forterre and Pouliquen 2006),
elasto-viscoplastic as in continuum granular MPM (Dunatunga and Kamrin 2015); hypoelastic
(Jaumann rate, :mod:`fempm.materials.hypoelastic`), plane strain in 2D.

The grains flow when the shear stress :math:`\tau = \sqrt{J_2}` reaches the friction the
inertial number allows,

.. math::
    \tau = \mu(I)\, P, \qquad
    \mu(I) = \mu_s + \frac{\mu_2 - \mu_s}{I_0 / I + 1}, \qquad
    I = \frac{\dot\gamma^p d}{\sqrt{P / \rho_s}},

with :math:`P = -\tfrac13 \mathrm{tr}\,\sigma` the pressure, :math:`\dot\gamma^p` the plastic
shear rate (:math:`\tau` falls by :math:`G \dot\gamma^p \Delta t` over a step), :math:`d` the
grain diameter and :math:`\rho_s` the grains' density. Below :math:`\mu_s P` the material is
elastic (a Drucker-Prager cone :math:`\sqrt{J_2} = \mu_s P` at rest); the friction rises to
:math:`\mu_2` at high rates. The flow is isochoric (no dilatancy), and where the pressure would
turn to tension the grains separate and carry no stress. Unlike a rate-independent law this one
has a length, :math:`d` (the silo's discharge with it and Beverloo's
:math:`W \propto \sqrt g\, D^{3/2}`, measured: docs/boundaries.md). The return mapping over a step
solves a quadratic for :math:`\Delta\gamma` exactly
(:func:`fempm.kernels.granular.mu_i_return`, compiled).

Defaults: the glass beads of Jop et al. (:math:`\mu_s = \tan 20.9°`,
:math:`\mu_2 = \tan 32.76°`, :math:`I_0 = 0.279`, :math:`d = 0.53` mm,
:math:`\rho_s = 2450` kg/m³).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from fempm.kernels.granular import mu_i_return
from fempm.kernels.plasticity import split
from fempm.materials.base import Internal
from fempm.materials.hypoelastic import SIGMA_ZZ, HypoelasticPlastic

__all__ = ["MuI"]


@dataclass(frozen=True)
class MuI(HypoelasticPlastic):
    r"""The local :math:`\mu(I)` rheology, elasto-viscoplastic (see the module).

    Args:
        E: Young's modulus of the granular skeleton.
        nu: Poisson's ratio.
        mu_s: The static friction coefficient :math:`\mu_s > 0`.
        mu_2: The limiting friction at high inertial numbers, :math:`\mu_2 \ge \mu_s`.
        I_0: The inertial number at which :math:`\mu` is halfway, :math:`I_0 > 0`.
        grain_diameter: :math:`d > 0`.
        grain_density: :math:`\rho_s > 0`, the grains' own density.

    Note:
        Rate-dependent (``rate_dependent``): its stress depends on the step's length as well as
        on the increment; the implicit step passes its ``dt`` to the stress and to the
        algorithmic tangent (:meth:`return_tangent`).
    """

    mu_s: float = float(np.tan(np.radians(20.9)))
    mu_2: float = float(np.tan(np.radians(32.76)))
    I_0: float = 0.279
    grain_diameter: float = 0.53e-3
    grain_density: float = 2450.0
    history: ClassVar[tuple[Internal, ...]] = (Internal("eps_p"), SIGMA_ZZ)
    #: the stress depends on the rate, not only on the increment (the implicit step passes it dt)
    rate_dependent: ClassVar[bool] = True

    def __post_init__(self):
        super().__post_init__()
        if not 0.0 < self.mu_s < np.inf:
            raise ValueError(f"MuI needs 0 < mu_s (got {self.mu_s})")
        if not self.mu_s <= self.mu_2 < np.inf:
            raise ValueError(f"MuI needs mu_s <= mu_2 (got mu_s={self.mu_s}, mu_2={self.mu_2})")
        for name in ("I_0", "grain_diameter", "grain_density"):
            if not 0.0 < getattr(self, name) < np.inf:
                raise ValueError(f"MuI needs {name} > 0 (got {getattr(self, name)})")

    def friction(self, I: npt.ArrayLike) -> npt.NDArray:
        r""":math:`\mu(I)` of inertial numbers ``I``."""
        I = np.asarray(I, dtype=np.float64)
        return self.mu_s + (self.mu_2 - self.mu_s) * I / (self.I_0 + I)

    def inertial_number(self, shear_rate: npt.ArrayLike, pressure: npt.ArrayLike) -> npt.NDArray:
        r""":math:`I = \dot\gamma d / \sqrt{P / \rho_s}` of shear rates and (positive) pressures."""
        return np.asarray(shear_rate) * self.grain_diameter / np.sqrt(np.asarray(pressure) / self.grain_density)

    def return_map(self, S: npt.NDArray, eps_p: npt.NDArray, dt: float) -> tuple[npt.NDArray, npt.NDArray]:
        """(returned stresses, equivalent plastic strains) of trial (n, 3, 3) stresses over a
        step ``dt`` (:func:`fempm.kernels.granular.mu_i_return`, compiled)."""
        return mu_i_return(S, eps_p, dt, self.mu_s, self.mu_2, self.I_0, self.grain_diameter, self.grain_density,
                           self.lame[1])

    def return_tangent(self, S: npt.NDArray, eps_p: npt.NDArray, d: int, dt: float = 1.0) -> npt.NDArray:
        r""":math:`\partial \sigma_{ij} / \partial \sigma^{tr}_{ab}` (n, 3, 3, 3, 3) of the return
        over a step ``dt`` of trial stresses ``S`` (the algorithmic tangent). Where the grains
        flow, :math:`\Delta\gamma` solves
        :math:`h = \tau^{tr} - G\Delta\gamma - \mu(I) P = 0` with :math:`I = c\,\Delta\gamma`,
        :math:`c = d / (\Delta t \sqrt{P/\rho_s})` (so :math:`\partial I / \partial P = -I / (2P)`):

        .. math::
            \mathrm{d}\Delta\gamma = \frac{\mathrm{d}\tau^{tr}
                + \big(\tfrac12 \mu'(I)\, I - \mu(I)\big)\, \mathrm{d}P}{G + \mu'(I)\, c P},
            \qquad \mu'(I) = \frac{(\mu_2 - \mu_s) I_0}{(I_0 + I)^2},

        with :math:`\partial \tau^{tr} / \partial \sigma^{tr} = s^{tr} / (2 \tau^{tr})`,
        :math:`\partial P / \partial \sigma^{tr} = -I / 3`, and the returned
        :math:`\sigma = (\tau / \tau^{tr})\, s^{tr} - P I`, :math:`\tau = \tau^{tr} - G\Delta\gamma`.
        Elastic: the identity; separated grains (zero stress): zero."""
        G = self.lame[1]
        p, dev, ss = split(S)
        P = -p
        tau = np.sqrt(0.5 * ss)
        free = P <= 0.0
        flows = ~free & (tau - self.mu_s * P > 0.0)
        returned, _ = self.return_map(S, eps_p, dt)
        t = np.where(flows, tau, 1.0)
        Pf = np.where(flows, P, 1.0)
        tau_new = np.sqrt(0.5 * split(returned)[2])
        dgamma = np.where(flows, (tau - tau_new) / G, 0.0)
        c = self.grain_diameter / (dt * np.sqrt(Pf / self.grain_density))
        inertial = c * dgamma
        slope = (self.mu_2 - self.mu_s) * self.I_0 / (self.I_0 + inertial) ** 2
        e = np.eye(3)
        iso = np.einsum("ij,ab->ijab", e, e) / 3.0
        ddev = np.einsum("ia,jb->ijab", e, e) - iso  # d s_ij / d S_ab
        dtau = dev / (2.0 * t[:, None, None])
        dP = np.broadcast_to(-e / 3.0, S.shape)
        ddg = (dtau + (0.5 * slope * inertial - self.friction(inertial))[:, None, None] * dP) \
            / (G + slope * c * Pf)[:, None, None]
        scale = np.where(flows, tau_new / t, 1.0)
        dscale = np.where(flows[:, None, None], (dtau - G * ddg - scale[:, None, None] * dtau) / t[:, None, None], 0.0)
        R = np.einsum("nij,nab->nijab", dev, dscale) + scale[:, None, None, None, None] * ddev + iso
        R[free] = 0.0
        return R

    def stress(self, F, L, sigma, dt, rho, state) -> npt.NDArray:
        S, state["eps_p"] = self.return_map(self.trial(L, sigma, dt, state), state["eps_p"], dt)
        return self.finish(S, L.shape[1], state)
