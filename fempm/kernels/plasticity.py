r"""The hypoelastic predictor and the J2 return mapping, per particle.

* :func:`jaumann_trial`: with :math:`D = \mathrm{sym}\, L`, :math:`W = \mathrm{skew}\, L` (as
  3 x 3, plane strain in 2D with the out-of-plane stress ``zz``),

  .. math::
      \sigma^{tr} = \sigma + \Delta t\,(W\sigma - \sigma W) + \Delta t\,(\lambda\, \mathrm{tr} D\, I + 2\mu D)

  (:class:`fempm.materials.hypoelastic.HypoelasticPlastic`);
* :func:`von_mises_return`: the radial return of :class:`fempm.materials.VonMises`,
  :math:`s = (1 - 3\mu\Delta\gamma / q^{tr})\, s^{tr}` with
  :math:`\Delta\gamma = \max(0, f^{tr}) / (3\mu + H)`, the pressure unchanged.

* :func:`drucker_prager_return`: the return of :class:`fempm.materials.DruckerPrager` onto its
  cone (or its apex), then the tension cut-off :math:`p \le p_t` along the hydrostatic axis.

The numpy functions (``*_numpy``) define what they compute; the compiled ones agree with them
to round-off (``tests/kernels/test_kernels.py``). Both return new arrays.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from fempm.kernels.choice import INLINE, pick
from fempm.kernels.kinematics import skew, sym

__all__ = [
    "drucker_prager_return", "drucker_prager_return_numpy", "invariants_at", "jaumann_trial", "jaumann_trial_numpy",
    "split", "to3", "von_mises_return", "von_mises_return_numpy",
]


def to3(sigma: npt.NDArray, zz: npt.NDArray | None) -> npt.NDArray:
    """(n, d, d) stresses as (n, 3, 3), with ``zz`` the out-of-plane stress in 2D."""
    n, d = len(sigma), sigma.shape[1]
    if d == 3:
        return np.array(sigma, dtype=float)
    out = np.zeros((n, 3, 3))
    out[:, :2, :2] = sigma
    out[:, 2, 2] = zz
    return out


def split(S: npt.NDArray) -> tuple[npt.NDArray, npt.NDArray, npt.NDArray]:
    r"""(:math:`p = \tfrac13 \mathrm{tr}\, S`, the deviator :math:`s = S - p I`, :math:`s : s`)
    of (n, 3, 3) stresses."""
    p = np.trace(S, axis1=1, axis2=2) / 3
    dev = S - p[:, None, None] * np.eye(3)
    return p, dev, np.einsum("nij,nij->n", dev, dev)


def jaumann_trial_numpy(L, sigma, zz, dt, lam, mu):
    n, d = L.shape[0], L.shape[1]
    L3 = np.zeros((n, 3, 3))
    L3[:, :d, :d] = L
    S = to3(sigma, zz)
    D, W = sym(L3), skew(L3)
    S = S + dt * (W @ S - S @ W)
    S += dt * 2 * mu * D
    S[:, range(3), range(3)] += (dt * lam * np.trace(D, axis1=1, axis2=2))[:, None]
    return S


def von_mises_return_numpy(S, eps_p, yield_stress, hardening, mu):
    p, dev, ss = split(S)
    q = np.sqrt(1.5 * ss)
    f = q - (yield_stress + hardening * eps_p)
    plastic = f > 0
    dgamma = np.where(plastic, f, 0.0) / (3 * mu + hardening)
    scale = np.where(plastic, 1.0 - 3 * mu * dgamma / np.where(plastic, q, 1.0), 1.0)
    return dev * scale[:, None, None] + p[:, None, None] * np.eye(3), eps_p + dgamma


def drucker_prager_return_numpy(S, eps_p, eta, k, eta_bar, p_t, G, K):
    p, dev, ss = split(S)
    root = np.sqrt(0.5 * ss)
    f = root + eta * p - k
    plastic = f > 0
    dgamma = np.where(plastic, f, 0.0) / (G + K * eta * eta_bar)
    new_root = root - G * dgamma
    apex = plastic & (new_root < 0)
    cone_ = plastic & ~apex
    scale = np.where(cone_, new_root / np.where(cone_, root, 1.0), 1.0)
    scale[apex] = 0.0
    p = np.where(cone_, p - K * eta_bar * dgamma, p)
    p[apex] = k / eta if eta > 0 else p[apex]
    deps = np.where(cone_, dgamma, 0.0) / np.sqrt(3.0) + np.where(apex, root, 0.0) / (G * np.sqrt(3.0))
    p = np.minimum(p, p_t)  # the tension cut-off, along the hydrostatic axis
    return dev * scale[:, None, None] + p[:, None, None] * np.eye(3), eps_p + deps


try:
    from numba import njit

    @njit(cache=True)
    def _jaumann_trial(L, sigma, zz, dt, lam, mu, S):  # pragma: no cover - compiled
        n, d = L.shape[0], L.shape[1]
        s0 = np.zeros((3, 3))
        Lp = np.zeros((3, 3))
        for p in range(n):
            for i in range(d):
                for j in range(d):
                    s0[i, j] = sigma[p, i, j]
                    Lp[i, j] = L[p, i, j]
            if d == 2:
                s0[2, 2] = zz[p]
            tr = Lp[0, 0] + Lp[1, 1] + Lp[2, 2]
            for i in range(3):
                for j in range(3):
                    rot = 0.0
                    for k in range(3):
                        rot += 0.5 * (Lp[i, k] - Lp[k, i]) * s0[k, j] - s0[i, k] * 0.5 * (Lp[k, j] - Lp[j, k])
                    v = s0[i, j] + dt * rot
                    v += dt * 2 * mu * 0.5 * (Lp[i, j] + Lp[j, i])
                    if i == j:
                        v += dt * lam * tr
                    S[p, i, j] = v

    @njit(inline=INLINE)
    def invariants_at(S, p):  # pragma: no cover - compiled
        """(pressure, s : s) of the stress S[p] (3 x 3)."""
        pr = (S[p, 0, 0] + S[p, 1, 1] + S[p, 2, 2]) / 3
        ss = 0.0
        for i in range(3):
            for j in range(3):
                dv = S[p, i, j] - pr if i == j else S[p, i, j]
                ss += dv * dv
        return pr, ss

    @njit(inline=INLINE)
    def _returned(S, p, pr, scale, pr_new, out):  # pragma: no cover - compiled
        """out[p] = scale * dev(S[p]) + pr_new I, with pr the pressure of S[p]."""
        for i in range(3):
            for j in range(3):
                dv = S[p, i, j] - pr if i == j else S[p, i, j]
                out[p, i, j] = dv * scale + pr_new if i == j else dv * scale

    @njit(cache=True)
    def _von_mises_return(S, eps_p, yield_stress, hardening, mu, out, eps_out):  # pragma: no cover - compiled
        for p in range(S.shape[0]):
            pr, ss = invariants_at(S, p)
            q = np.sqrt(1.5 * ss)
            f = q - (yield_stress + hardening * eps_p[p])
            dgamma = 0.0
            scale = 1.0
            if f > 0:
                dgamma = f / (3 * mu + hardening)
                scale = 1.0 - 3 * mu * dgamma / q
            eps_out[p] = eps_p[p] + dgamma
            _returned(S, p, pr, scale, pr, out)

    @njit(cache=True)
    def _drucker_prager_return(S, eps_p, eta, k, eta_bar, p_t, G, K, out, eps_out):  # pragma: no cover - compiled
        sqrt3 = np.sqrt(3.0)
        for p in range(S.shape[0]):
            pr, ss = invariants_at(S, p)
            root = np.sqrt(0.5 * ss)
            f = root + eta * pr - k
            scale = 1.0
            deps = 0.0
            pr_new = pr
            if f > 0:
                dgamma = f / (G + K * eta * eta_bar)
                new_root = root - G * dgamma
                if new_root < 0:  # past the apex
                    scale = 0.0
                    if eta > 0:
                        pr_new = k / eta
                    deps = root / (G * sqrt3)
                else:
                    scale = new_root / root
                    pr_new = pr - K * eta_bar * dgamma
                    deps = dgamma / sqrt3
            eps_out[p] = eps_p[p] + deps
            _returned(S, p, pr, scale, min(pr_new, p_t), out)

    def drucker_prager_return_numba(S, eps_p, eta, k, eta_bar, p_t, G, K):
        out, eps_out = np.empty_like(S), np.empty(len(S))
        _drucker_prager_return(np.ascontiguousarray(S), np.ascontiguousarray(eps_p, dtype=np.float64), float(eta),
                               float(k), float(eta_bar), float(p_t), float(G), float(K), out, eps_out)
        return out, eps_out

    def jaumann_trial_numba(L, sigma, zz, dt, lam, mu):
        n, d = L.shape[0], L.shape[1]
        S = np.empty((n, 3, 3))
        zz = np.zeros(n) if zz is None or d == 3 else np.ascontiguousarray(zz, dtype=np.float64)
        _jaumann_trial(np.ascontiguousarray(L), np.ascontiguousarray(sigma), zz, float(dt), float(lam), float(mu), S)
        return S

    def von_mises_return_numba(S, eps_p, yield_stress, hardening, mu):
        out, eps_out = np.empty_like(S), np.empty(len(S))
        _von_mises_return(np.ascontiguousarray(S), np.ascontiguousarray(eps_p, dtype=np.float64),
                          float(yield_stress), float(hardening), float(mu), out, eps_out)
        return out, eps_out
except ImportError:  # pragma: no cover
    def invariants_at(S, p):
        """(pressure, s : s) of the stress S[p] (3 x 3)."""
        pr = np.trace(S[p]) / 3
        dev = S[p] - pr * np.eye(3)
        return pr, float(np.sum(dev * dev))

    jaumann_trial_numba, von_mises_return_numba = jaumann_trial_numpy, von_mises_return_numpy
    drucker_prager_return_numba = drucker_prager_return_numpy


def jaumann_trial(L: npt.NDArray, sigma: npt.NDArray, zz: npt.NDArray | None, dt: float, lam: float,
                  mu: float) -> npt.NDArray:
    """The trial stresses (n, 3, 3) of (n, d, d) velocity gradients and stresses (d = 2, 3)."""
    return pick(jaumann_trial_numba, jaumann_trial_numpy)(L, sigma, zz, dt, lam, mu)


def von_mises_return(S: npt.NDArray, eps_p: npt.NDArray, yield_stress: float, hardening: float,
                     mu: float) -> tuple[npt.NDArray, npt.NDArray]:
    """(returned (n, 3, 3) stresses, equivalent plastic strains) of trial stresses."""
    return pick(von_mises_return_numba, von_mises_return_numpy)(S, eps_p, yield_stress, hardening, mu)


def drucker_prager_return(S: npt.NDArray, eps_p: npt.NDArray, eta: float, k: float, eta_bar: float, p_t: float,
                          G: float, K: float) -> tuple[npt.NDArray, npt.NDArray]:
    """(returned (n, 3, 3) stresses, equivalent plastic strains) of trial stresses; ``eta``,
    ``k`` = xi c, ``eta_bar``, ``p_t`` of :meth:`fempm.materials.DruckerPrager.parameters`."""
    return pick(drucker_prager_return_numba, drucker_prager_return_numpy)(S, eps_p, eta, k, eta_bar, p_t, G, K)
