r"""Kinematics and the elastic laws, per particle.

* :func:`sym`, :func:`skew`: the rate of deformation :math:`D = \mathrm{sym}\, L` and the
  spin :math:`W = \mathrm{skew}\, L` of a batch (n, d, d).
* :func:`deform`: :math:`F^+ = (I + \Delta t\, L) F`, :math:`J = \det F^+` (closed form in
  1, 2 and 3 dimensions), in one pass and without temporaries.
* :func:`neo_hookean_stress`: :math:`\sigma = \frac{\mu}{J}(F F^T - I) + \frac{\lambda \ln J}{J} I`
  (:class:`fempm.materials.NeoHookean`, whose numpy formula is the reference).
* :func:`elastic_energy`: the stored energy :math:`W(F)` of either law (``code``
  :data:`~fempm.kernels.particle_checks.NEO_HOOKEAN` or ``LINEAR_ELASTIC``).
* :func:`linear_elastic_stress`: :math:`\sigma = \lambda\, \mathrm{tr}\,\varepsilon\, I +
  2\mu \varepsilon`, :math:`\varepsilon = \mathrm{sym}(F) - I`
  (:class:`fempm.materials.LinearElastic`).
"""

from __future__ import annotations

import functools
from types import SimpleNamespace

import numpy as np
import numpy.typing as npt

from fempm.kernels.choice import INLINE, pick
from fempm.kernels.particle_checks import LINEAR_ELASTIC, NEO_HOOKEAN

__all__ = [
    "deform", "deform_numpy", "elastic_energy", "elastic_energy_numpy", "linear_elastic_stress",
    "linear_elastic_stress_numpy", "neo_hookean_stress", "neo_hookean_stress_numpy", "skew", "sym",
]


def sym(A: npt.NDArray) -> npt.NDArray:
    """(A + A^T) / 2 for a batch A (n, d, d)."""
    return 0.5 * (A + np.swapaxes(A, 1, 2))


def skew(A: npt.NDArray) -> npt.NDArray:
    """(A - A^T) / 2 for a batch A (n, d, d)."""
    return 0.5 * (A - np.swapaxes(A, 1, 2))


def deform_numpy(F, L, dt):
    d = F.shape[1]
    Fn = (np.eye(d) + dt * L) @ F
    with np.errstate(invalid="ignore"):
        return Fn, np.linalg.det(Fn)


def neo_hookean_stress_numpy(F, lam, mu):
    d = F.shape[1]
    J = np.linalg.det(F)
    B = F @ np.swapaxes(F, 1, 2)
    return (mu * (B - np.eye(d)) + (lam * np.log(J))[:, None, None] * np.eye(d)) / J[:, None, None]


def linear_elastic_stress_numpy(F, lam, mu):
    d = F.shape[1]
    eps = sym(F) - np.eye(d)
    return lam * np.trace(eps, axis1=1, axis2=2)[:, None, None] * np.eye(d) + 2 * mu * eps


def elastic_energy_numpy(code: int, F: npt.NDArray, lam: float, mu: float) -> npt.NDArray:
    """The stored energy per reference volume W(F) (n,) of the compiled law ``code``
    (``NEO_HOOKEAN`` or ``LINEAR_ELASTIC``)."""
    d = F.shape[1]
    if code == NEO_HOOKEAN:
        lnJ = np.log(np.linalg.det(F))
        return 0.5 * mu * (np.einsum("nij,nij->n", F, F) - d) - mu * lnJ + 0.5 * lam * lnJ**2
    eps = sym(F) - np.eye(d)
    return 0.5 * lam * np.trace(eps, axis1=1, axis2=2) ** 2 + mu * np.einsum("nij,nij->n", eps, eps)


try:
    from numba import njit

    @njit(inline=INLINE)
    def _det(A, p):  # pragma: no cover - compiled
        d = A.shape[1]
        if d == 1:
            return A[p, 0, 0]
        if d == 2:
            return A[p, 0, 0] * A[p, 1, 1] - A[p, 0, 1] * A[p, 1, 0]
        return (A[p, 0, 0] * (A[p, 1, 1] * A[p, 2, 2] - A[p, 1, 2] * A[p, 2, 1])
                - A[p, 0, 1] * (A[p, 1, 0] * A[p, 2, 2] - A[p, 1, 2] * A[p, 2, 0])
                + A[p, 0, 2] * (A[p, 1, 0] * A[p, 2, 1] - A[p, 1, 1] * A[p, 2, 0]))

    @njit(inline=INLINE)
    def neo_hookean_at(F, p, d, J, lam, mu, sigma):  # pragma: no cover - compiled
        """sigma[p] of the neo-Hookean law from F[p] (d x d) with J = det F[p] > 0."""
        inv = 1.0 / J
        vol = lam * np.log(J)
        for i in range(d):
            for j in range(d):
                b = 0.0
                for k in range(d):
                    b += F[p, i, k] * F[p, j, k]
                if i == j:
                    sigma[p, i, j] = (mu * (b - 1.0) + vol) * inv
                else:
                    sigma[p, i, j] = mu * b * inv

    @njit(inline=INLINE)
    def linear_elastic_at(F, p, d, lam, mu, sigma):  # pragma: no cover - compiled
        """sigma[p] of the linear elastic law from F[p] (d x d)."""
        tr = 0.0
        for i in range(d):
            tr += F[p, i, i] - 1.0
        for i in range(d):
            for j in range(d):
                e = 0.5 * (F[p, i, j] + F[p, j, i])
                if i == j:
                    sigma[p, i, j] = lam * tr + 2.0 * mu * (e - 1.0)
                else:
                    sigma[p, i, j] = 2.0 * mu * e

    @njit(inline=INLINE)
    def deform_at(F, p, dt, Lp, D, Fn):  # pragma: no cover - compiled
        r""":math:`F_p \leftarrow (I + \Delta t L_p) F_p` (``Fn`` scratch); returns :math:`\det F_p`."""
        for i in range(D):
            for j in range(D):
                t = F[p, i, j]
                for q in range(D):
                    t += dt * Lp[i, q] * F[p, q, j]
                Fn[i, j] = t
        for i in range(D):
            for j in range(D):
                F[p, i, j] = Fn[i, j]
        return _det(F, p)

    @njit(inline=INLINE)
    def law_at(code, F, p, D, J, lam, mu, sigma):  # pragma: no cover - compiled
        """``sigma[p]`` of the compiled law ``code`` (else left as it is) from ``F[p]``, J > 0."""
        if code == NEO_HOOKEAN:
            neo_hookean_at(F, p, D, J, lam, mu, sigma)
        elif code == LINEAR_ELASTIC:
            linear_elastic_at(F, p, D, lam, mu, sigma)

    @njit(inline=INLINE)
    def energy_at(code, F, p, d, lam, mu):  # pragma: no cover - compiled
        r"""The stored energy per reference volume :math:`W(F_p)` of the compiled law ``code``
        (``NEO_HOOKEAN``: :math:`\frac{\mu}{2}(F:F - d) - \mu
        \ln J + \frac{\lambda}{2} (\ln J)^2`; ``LINEAR_ELASTIC``: :math:`\frac{\lambda}{2}
        (\mathrm{tr}\,\varepsilon)^2 + \mu\, \varepsilon:\varepsilon`), 0 for any other code
        (the materials' ``energy_density`` are the reference)."""
        if code == NEO_HOOKEAN:
            ff = 0.0
            for i in range(d):
                for j in range(d):
                    ff += F[p, i, j] * F[p, i, j]
            lnJ = np.log(_det(F, p))
            return 0.5 * mu * (ff - d) - mu * lnJ + 0.5 * lam * lnJ * lnJ
        if code == LINEAR_ELASTIC:
            tr = 0.0
            ee = 0.0
            for i in range(d):
                tr += F[p, i, i] - 1.0
                for j in range(d):
                    e = 0.5 * (F[p, i, j] + F[p, j, i]) - (1.0 if i == j else 0.0)
                    ee += e * e
            return 0.5 * lam * tr * tr + mu * ee
        return 0.0

    @njit(inline=INLINE)
    def add_totals(acc, p, mass, v, F, volume0, law, lam, mu, d):  # pragma: no cover - compiled
        r"""``acc`` (3 + d) += particle ``p``'s :math:`[\tfrac12 M_p |v_p|^2,\ V^0_p W(F_p),\ M_p |v_p|,
        \ M_p v_p]` (``law``, ``lam``, ``mu``: its body's law code and Lame constants; W of the
        compiled laws, 0 for the others)."""
        m = mass[p]
        w2 = 0.0
        for j in range(d):
            w2 += v[p, j] * v[p, j]
            acc[3 + j] += m * v[p, j]
        acc[0] += 0.5 * m * w2
        acc[1] += volume0[p] * energy_at(law, F, p, d, lam, mu)
        acc[2] += m * np.sqrt(w2)

    @functools.cache
    def _passes(d: int) -> SimpleNamespace:
        """The passes of particles of dimension ``d`` (``deform``, ``neo_hookean``,
        ``linear_elastic``, ``energy``), the loops' sizes compile-time constants (2-5x as fast as
        read at run time; each compiled at its first call)."""

        @njit(cache=True, error_model="numpy")
        def deform(F, L, dt, Fn, J):  # pragma: no cover - compiled
            for p in range(F.shape[0]):
                for i in range(d):
                    for j in range(d):
                        s = F[p, i, j]
                        for k in range(d):
                            s += dt * L[p, i, k] * F[p, k, j]
                        Fn[p, i, j] = s
                J[p] = _det(Fn, p)

        @njit(cache=True, error_model="numpy")
        def neo_hookean(F, lam, mu, sigma):  # pragma: no cover - compiled
            for p in range(F.shape[0]):
                neo_hookean_at(F, p, d, _det(F, p), lam, mu, sigma)

        @njit(cache=True, error_model="numpy")
        def linear_elastic(F, lam, mu, sigma):  # pragma: no cover - compiled
            for p in range(F.shape[0]):
                linear_elastic_at(F, p, d, lam, mu, sigma)

        @njit(cache=True, error_model="numpy")
        def energy(code, F, lam, mu):  # pragma: no cover - compiled
            W = np.empty(F.shape[0])
            for p in range(F.shape[0]):
                W[p] = energy_at(code, F, p, d, lam, mu)
            return W

        return SimpleNamespace(deform=deform, neo_hookean=neo_hookean, linear_elastic=linear_elastic, energy=energy)

    def deform_numba(F, L, dt):
        Fn, J = np.empty_like(F), np.empty(len(F))
        _passes(F.shape[1]).deform(F, L, float(dt), Fn, J)
        return Fn, J

    def neo_hookean_stress_numba(F, lam, mu):
        sigma = np.empty_like(F)
        _passes(F.shape[1]).neo_hookean(F, float(lam), float(mu), sigma)
        return sigma

    def linear_elastic_stress_numba(F, lam, mu):
        sigma = np.empty_like(F)
        _passes(F.shape[1]).linear_elastic(F, float(lam), float(mu), sigma)
        return sigma

    def elastic_energy_numba(code, F, lam, mu):
        return _passes(F.shape[1]).energy(int(code), np.ascontiguousarray(F), float(lam), float(mu))
except ImportError:  # pragma: no cover
    deform_numba, neo_hookean_stress_numba, linear_elastic_stress_numba, elastic_energy_numba = (
        deform_numpy, neo_hookean_stress_numpy, linear_elastic_stress_numpy, elastic_energy_numpy)


def deform(F: npt.NDArray, L: npt.NDArray, dt: float) -> tuple[npt.NDArray, npt.NDArray]:
    """(F^+, J) for (n, d, d) ``F`` and ``L``; J is NaN or inf where F^+ is not finite."""
    return pick(deform_numba, deform_numpy)(F, L, dt)


def neo_hookean_stress(F: npt.NDArray, lam: float, mu: float) -> npt.NDArray:
    return pick(neo_hookean_stress_numba, neo_hookean_stress_numpy)(F, lam, mu)


def linear_elastic_stress(F: npt.NDArray, lam: float, mu: float) -> npt.NDArray:
    return pick(linear_elastic_stress_numba, linear_elastic_stress_numpy)(F, lam, mu)


def elastic_energy(code: int, F: npt.NDArray, lam: float, mu: float) -> npt.NDArray:
    return pick(elastic_energy_numba, elastic_energy_numpy)(code, F, lam, mu)
