r"""Hypoelastic-plastic laws: the shared elastic predictor, with the Jaumann rate.

Over a step, with :math:`D = \mathrm{sym}\, L` and :math:`W = \mathrm{skew}\, L`,

.. math::
    \sigma^{rot} = \sigma + \Delta t\,(W\sigma - \sigma W), \qquad
    \sigma^{tr} = \sigma^{rot} + \Delta t\,(\lambda\, \mathrm{tr} D\, I + 2\mu D),

then the law's return mapping brings :math:`\sigma^{tr}` back onto its yield surface. The
Jaumann rate makes the update objective (a superposed rigid rotation rotates the stress);
the rotation term is first order in :math:`\Delta t` (the usual explicit MPM choice, as in
Uintah and CB-Geo). In 2D the state is plane strain: :math:`D_{zz} = 0`, and the out-of-plane
stress :math:`\sigma_{zz}`, which the yield functions need, is kept as the internal variable
``sigma_zz``. All arithmetic runs on 3 x 3 stresses, vectorized over particles.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from fempm.kernels.plasticity import jaumann_trial, split, to3
from fempm.materials.base import Internal, IsotropicElastic

__all__ = ["SIGMA_ZZ", "HypoelasticPlastic"]

#: the out-of-plane stress of a plane-strain state
SIGMA_ZZ = Internal("sigma_zz")


@dataclass(frozen=True)
class HypoelasticPlastic(IsotropicElastic):
    """Elastic predictor (Jaumann rate, plane strain in 2D) for the return mappings of
    :class:`fempm.materials.VonMises` and :class:`fempm.materials.DruckerPrager`."""

    energy_from_stress: ClassVar[bool] = True  # the stored energy is the elastic part, from the stress

    def trial(self, L: npt.NDArray, sigma: npt.NDArray, dt: float, state: dict) -> npt.NDArray:
        """The trial stresses (n, 3, 3) of a step with velocity gradients ``L``
        (:func:`fempm.kernels.plasticity.jaumann_trial`, compiled)."""
        d = L.shape[1]
        if d not in (2, 3):
            raise ValueError(f"{type(self).__name__} needs a 2D (plane strain) or 3D space, not {d}D")
        return jaumann_trial(L, sigma, state.get("sigma_zz"), dt, *self.lame)

    def trial_tangent(self, sigma: npt.NDArray, state: dict) -> npt.NDArray:
        r""":math:`\partial \sigma^{tr}_{ij} / \partial G_{kl}` (n, 3, 3, d, d) of the trial stress of
        an increment, :math:`L\,\Delta t = G` (:mod:`fempm.materials.tangent`), on (n, d, d)
        stresses at the step's start :math:`S`:

        .. math::
            \tfrac12 (\delta_{ik} S_{lj} - \delta_{il} S_{kj} - S_{ik} \delta_{jl} + S_{il} \delta_{jk})
            + \lambda\, \delta_{ij} \delta_{kl} + \mu (\delta_{ik} \delta_{jl} + \delta_{il} \delta_{jk}).
        """
        d = sigma.shape[1]
        lam, mu = self.lame
        S = to3(sigma, state.get("sigma_zz"))
        e3, e = np.eye(3), np.eye(3)[:, :d]
        Sr, Sc = S[:, :d, :], S[:, :, :d]  # S_lj and S_ik with l, k < d
        T = 0.5 * (np.einsum("ik,nlj->nijkl", e, Sr) - np.einsum("il,nkj->nijkl", e, Sr)
                   - np.einsum("nik,jl->nijkl", Sc, e) + np.einsum("nil,jk->nijkl", Sc, e))
        T += lam * np.einsum("ij,kl->ijkl", e3, np.eye(d)) + mu * (np.einsum("ik,jl->ijkl", e, e)
                                                                   + np.einsum("il,jk->ijkl", e, e))
        return T

    def tangent(self, F, G, sigma, state, **rate) -> npt.NDArray:
        r""":math:`\partial \sigma / \partial G` (n, d, d, d, d) of the increment (the consistent,
        algorithmic tangent): the return mapping's derivative (``return_tangent``) applied to
        the trial stress's (:meth:`trial_tangent`), at the step's internal variables ``state``;
        ``rate``: the step's ``dt`` for a rate-dependent law's return (:class:`fempm.materials.MuI`)."""
        d = G.shape[1]
        S = self.trial(G, sigma, 1.0, state)
        R = self.return_tangent(S, state["eps_p"], d, **rate)
        return np.einsum("nijab,nabkl->nijkl", R, self.trial_tangent(sigma, state))[:, :d, :d]

    def finish(self, S: npt.NDArray, d: int, state: dict) -> npt.NDArray:
        """The (n, d, d) stresses of returned (n, 3, 3) ones; the out-of-plane stress into ``state``."""
        if d == 2:
            state["sigma_zz"] = S[:, 2, 2].copy()
        return np.ascontiguousarray(S[:, :d, :d])

    def compliance_energy(self, S: npt.NDArray) -> npt.NDArray:
        r""":math:`\frac12 \sigma : C^{-1} : \sigma` (n,) of (n, 3, 3) stresses."""
        lam, mu = self.lame
        K = lam + 2 * mu / 3
        p, _, ss = split(S)
        return 0.5 * p**2 / K + ss / (4 * mu)

    def energy_density(self, F: npt.NDArray, sigma: npt.NDArray | None = None,
                       state: dict | None = None) -> npt.NDArray:
        r"""The stored elastic energy per reference volume, :math:`J\, \frac12 \sigma : C^{-1} : \sigma`
        (the plastic work is dissipated); 0 without the stresses."""
        if sigma is None:
            return np.zeros(len(F))
        S = to3(sigma, (state or {}).get("sigma_zz", np.zeros(len(F))))
        return np.linalg.det(F) * self.compliance_energy(S)
