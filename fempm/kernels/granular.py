r"""The return mapping of the local :math:`\mu(I)` rheology, per particle
(:class:`fempm.materials.MuI`).

With the pressure :math:`P = -\tfrac13 \mathrm{tr}\,\sigma^{tr}`, the shear stress
:math:`\tau^{tr} = \sqrt{J_2^{tr}} = |s^{tr}| / \sqrt2` of the elastic trial stress and the
excess :math:`S = \tau^{tr} - \mu_s P`:

* :math:`P \le 0`: the grains separate; the stress is zero (the cone's apex of a cohesionless
  law), and :math:`\varepsilon_p` grows by :math:`\tau^{tr} / (\sqrt3 G)`;
* :math:`S \le 0`: elastic, the trial stress stands;
* otherwise the material flows at the plastic shear rate :math:`\dot\gamma^p = \Delta\gamma /
  \Delta t` with :math:`\tau = \tau^{tr} - G \Delta\gamma = \mu(I) P`,
  :math:`I = \dot\gamma^p d / \sqrt{P / \rho_s}`,
  :math:`\mu(I) = \mu_s + (\mu_2 - \mu_s)\, I / (I_0 + I)`. With :math:`c = d / (\Delta t
  \sqrt{P / \rho_s})` (:math:`I = c \Delta\gamma`) this is the quadratic

  .. math::
      G c\, \Delta\gamma^2 + (G I_0 + (\mu_2 - \mu_s) P c - S c)\, \Delta\gamma - S I_0 = 0,

  whose one positive root is :math:`\Delta\gamma = 2 S I_0 / (b + \sqrt{b^2 + 4 G c S I_0})`
  (:math:`b` the middle coefficient; the form without cancellation). The deviator is scaled by
  :math:`\tau / \tau^{tr}`, the pressure kept (no dilatancy), and :math:`\varepsilon_p` grows by
  :math:`\Delta\gamma / \sqrt3` (as :class:`fempm.materials.DruckerPrager`'s).

The numpy function defines what is computed; the compiled one agrees with it to round-off
(``tests/materials/test_mu_i.py``). Both return new arrays.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from fempm.kernels.choice import pick
from fempm.kernels.plasticity import invariants_at, split

__all__ = ["mu_i_return", "mu_i_return_numpy"]


def mu_i_return_numpy(S, eps_p, dt, mu_s, mu_2, I_0, grain_d, grain_rho, G):
    p, dev, ss = split(S)
    P = -p
    tau = np.sqrt(0.5 * ss)
    excess = tau - mu_s * P
    free = P <= 0.0
    flows = ~free & (excess > 0.0)
    Pf = np.where(flows, P, 1.0)
    c = grain_d / (dt * np.sqrt(Pf / grain_rho))
    b = G * I_0 + (mu_2 - mu_s) * Pf * c - excess * c
    q = np.where(flows, excess, 0.0) * I_0
    dgamma = 2.0 * q / (b + np.sqrt(b * b + 4.0 * G * c * q) + np.where(flows, 0.0, 1.0))
    scale = np.where(flows, (tau - G * dgamma) / np.where(flows, tau, 1.0), 1.0)
    scale[free] = 0.0
    deps = np.where(flows, dgamma, 0.0) + np.where(free, tau / G, 0.0)
    out = dev * scale[:, None, None] + np.where(free, 0.0, p)[:, None, None] * np.eye(3)
    return out, eps_p + deps / np.sqrt(3.0)


try:
    from numba import njit

    @njit(cache=True)
    def _mu_i_return(S, eps_p, dt, mu_s, mu_2, I_0, grain_d, grain_rho, G, out, eps_out):  # pragma: no cover
        sqrt3 = np.sqrt(3.0)
        for n in range(S.shape[0]):
            p, ss = invariants_at(S, n)
            P = -p
            tau = np.sqrt(0.5 * ss)
            excess = tau - mu_s * P
            scale, keep, deps = 1.0, 1.0, 0.0
            if P <= 0.0:  # separated grains: no stress
                scale, keep, deps = 0.0, 0.0, tau / G
            elif excess > 0.0:
                c = grain_d / (dt * np.sqrt(P / grain_rho))
                b = G * I_0 + (mu_2 - mu_s) * P * c - excess * c
                q = excess * I_0
                dgamma = 2.0 * q / (b + np.sqrt(b * b + 4.0 * G * c * q))
                scale = (tau - G * dgamma) / tau
                deps = dgamma
            eps_out[n] = eps_p[n] + deps / sqrt3
            for i in range(3):
                for j in range(3):
                    dv = S[n, i, j] - p if i == j else S[n, i, j]
                    out[n, i, j] = dv * scale + keep * p if i == j else dv * scale

    def mu_i_return_numba(S, eps_p, dt, mu_s, mu_2, I_0, grain_d, grain_rho, G):
        out, eps_out = np.empty_like(S), np.empty(len(S))
        _mu_i_return(np.ascontiguousarray(S, dtype=np.float64), np.ascontiguousarray(eps_p, dtype=np.float64),
                     float(dt), float(mu_s), float(mu_2), float(I_0), float(grain_d), float(grain_rho), float(G),
                     out, eps_out)
        return out, eps_out
except ImportError:  # pragma: no cover
    mu_i_return_numba = mu_i_return_numpy


def mu_i_return(S: npt.NDArray, eps_p: npt.NDArray, dt: float, mu_s: float, mu_2: float, I_0: float,
                grain_d: float, grain_rho: float, G: float) -> tuple[npt.NDArray, npt.NDArray]:
    """(returned (n, 3, 3) stresses, equivalent plastic strains) of trial stresses over a step
    ``dt`` (see the module)."""
    return pick(mu_i_return_numba, mu_i_return_numpy)(S, eps_p, dt, mu_s, mu_2, I_0, grain_d, grain_rho, G)
