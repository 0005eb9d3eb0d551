r"""An exact solution with plasticity: a J2 strip hitting a wall in uniaxial strain.

The strip :math:`[0, 1] \times [0, H]` (plane strain, slip walls at :math:`y = 0, H`, so the
strain is uniaxial) of an elastic-perfectly plastic von Mises solid
(:class:`fempm.materials.VonMises`, :math:`\lambda, \mu`, yield stress :math:`\sigma_Y`,
density :math:`\rho`) moves at :math:`-v_0` along :math:`x` and meets a rigid wall at
:math:`x = 0` at :math:`t = 0`. In small-strain theory two waves run into it from the wall:

* the *elastic precursor*, speed :math:`c_e = \sqrt{(\lambda + 2\mu)/\rho}`, brings the strip to
  the Hugoniot elastic limit: in uniaxial strain :math:`\sigma_{xx} - \sigma_{yy} = 2\mu
  \varepsilon`, yielding at :math:`|\varepsilon| = \sigma_Y / 2\mu`, where
  :math:`\sigma_{HEL} = (\lambda + 2\mu) \sigma_Y / 2\mu`; behind it the strain is
  :math:`\varepsilon_2 = -\sigma_{HEL}/(\lambda + 2\mu)` and the velocity
  :math:`v_2 = -v_0 + \sigma_{HEL}/(\rho c_e)`;
* the *plastic wave*, speed :math:`c_p = \sqrt{K/\rho}` (:math:`K = \lambda + 2\mu/3`: at
  the yield surface the deviatoric stress no longer changes, only the pressure), brings the
  strip to rest, :math:`v_3 = 0`, with :math:`\varepsilon_3 = \varepsilon_2 + v_2/c_p`
  (the jump conditions :math:`[v] = -c\,[\varepsilon]` of a wave running in :math:`+x`).

The displacement is continuous and piecewise linear in :math:`X` and :math:`t`,

.. math::
    u = -v_0 t + \begin{cases}
      0, & X \ge c_e t,\\
      \varepsilon_2 (X - c_e t), & c_p t \le X < c_e t,\\
      \varepsilon_2 (c_p - c_e) t + \varepsilon_3 (X - c_p t), & X < c_p t,
    \end{cases}

which vanishes at the wall. It needs :math:`v_0 > \sigma_{HEL} / (\rho c_e)` (else the strip
bounces back elastically) and holds until the precursor reaches the free end,
:math:`t < 1/c_e`. The MPM loop integrates finite strains (the hypoelastic law with the
Jaumann rate): the difference is of the order of the strain (:math:`10^{-3}` here) relative
to the displacement jump across each wave, below the discretization errors of the study.
The velocity jumps, so the displacement error converges at most like :math:`h`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from fempm.materials.von_mises import VonMises
from fempm.verification.problem import Problem, as_columns

__all__ = ["PlasticImpact", "plastic_impact"]


@dataclass(frozen=True)
class PlasticImpact(Problem):
    """The strip of the module: ``E``, ``nu``, ``rho0``, ``yield_stress``, impact speed ``v0``,
    height ``H``; ``t_end`` as a fraction ``reach`` of the time the precursor takes to cross it."""

    E: float = 1e7
    nu: float = 0.3
    rho0: float = 1000.0
    yield_stress: float = 2e3
    v0: float = 0.1
    H: float = 0.25
    reach: float = 0.6

    def __post_init__(self):
        self.declare(name="plastic_impact", dim=2, has_body_force=False)
        if not self.v0 > self.hel / (self.rho0 * self.c_e):
            raise ValueError(f"PlasticImpact needs v0 > sigma_HEL / (rho c_e) = {self.hel / (self.rho0 * self.c_e):.4g} "
                             f"(got v0={self.v0}): the strip would not yield")

    @property
    def lame(self) -> tuple[float, float]:
        return self.E * self.nu / ((1 + self.nu) * (1 - 2 * self.nu)), self.E / (2 * (1 + self.nu))

    @property
    def material(self) -> VonMises:
        return VonMises(self.E, self.nu, yield_stress=self.yield_stress)

    @property
    def c_e(self) -> float:
        lam, mu = self.lame
        return float(np.sqrt((lam + 2 * mu) / self.rho0))

    @property
    def c_p(self) -> float:
        lam, mu = self.lame
        return float(np.sqrt((lam + 2 * mu / 3) / self.rho0))

    @property
    def hel(self) -> float:
        """The Hugoniot elastic limit :math:`\\sigma_{HEL}` (a compressive magnitude)."""
        lam, mu = self.lame
        return (lam + 2 * mu) * self.yield_stress / (2 * mu)

    @property
    def states(self) -> tuple[float, float, float]:
        """(:math:`\\varepsilon_2, v_2, \\varepsilon_3`) behind the precursor and the plastic wave."""
        lam, mu = self.lame
        eps2 = -self.hel / (lam + 2 * mu)
        v2 = -self.v0 + self.hel / (self.rho0 * self.c_e)
        return eps2, v2, eps2 + v2 / self.c_p

    @property
    def t_end(self) -> float:
        return self.reach / self.c_e

    @property
    def upper(self) -> tuple[float, ...]:
        return (1.0, self.H)

    def _x(self, X, t: float) -> tuple[npt.NDArray, npt.NDArray, npt.NDArray]:
        X = as_columns(X, 2)[:, 0]
        return X, X < self.c_p * t, (X >= self.c_p * t) & (X < self.c_e * t)

    def displacement(self, X, t: float) -> npt.NDArray:
        eps2, _, eps3 = self.states
        X, plastic, elastic = self._x(X, t)
        u = np.where(elastic, eps2 * (X - self.c_e * t), 0.0)
        u = np.where(plastic, eps2 * (self.c_p - self.c_e) * t + eps3 * (X - self.c_p * t), u) - self.v0 * t
        return np.column_stack([u, np.zeros_like(u)])

    def velocity(self, X, t: float) -> npt.NDArray:
        _, v2, _ = self.states
        X, plastic, elastic = self._x(X, t)
        v = np.where(plastic, 0.0, np.where(elastic, v2, -self.v0))
        return np.column_stack([v, np.zeros_like(v)])

    def deformation_gradient(self, X, t: float) -> npt.NDArray:
        eps2, _, eps3 = self.states
        X, plastic, elastic = self._x(X, t)
        F = np.zeros((len(X), 2, 2))
        F[:, 0, 0] = 1.0 + np.where(plastic, eps3, np.where(elastic, eps2, 0.0))
        F[:, 1, 1] = 1.0
        return F

    def body_force(self, X, t: float) -> npt.NDArray:
        return np.zeros((len(as_columns(X, 2)), 2))

    def walls(self):
        return [(0, 0.0, "slip"), (1, 0.0, "slip"), (1, self.H, "slip")]


def plastic_impact(**kw) -> PlasticImpact:
    """:class:`PlasticImpact` with the given parameters."""
    return PlasticImpact(**kw)
