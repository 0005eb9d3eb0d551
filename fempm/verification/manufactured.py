r"""Exact and manufactured solutions for convergence studies of the MPM loop.

Each problem is an exact motion :math:`x = X + u(X, t)` of a body with reference positions
:math:`X`, with vectorised ``displacement(X, t)``, ``velocity(X, t)``,
``deformation_gradient(X, t)`` and ``body_force(X, t)`` (per unit mass) for ``X`` of shape
(n, d) and a float ``t``, plus the material, the reference body, the background box and the
boundary conditions. The body force makes the motion exact for the balance of momentum in
the reference configuration,

.. math::
    \rho_0 \ddot u = \operatorname{Div} P + \rho_0 b
    \quad\Longrightarrow\quad b = \ddot u - \frac{1}{\rho_0} \operatorname{Div} P,

with :math:`P = J \sigma F^{-T}` the first Piola-Kirchhoff stress of the problem's material.
Each closed form below is derived in its docstring; ``tests/verification/test_manufactured.py``
checks it against finite differences of the exact motion.

* :func:`axis_aligned_1d`: 1D, both ends fixed (Steffen, Kirby and Berzins 2008);
* :func:`axis_aligned`: 2D/3D axis-aligned displacement (Wallstedt and Guilkey 2008);
* :func:`generalized_vortex`: rotation of an annulus (Kamojjala, Brannon, Sadeghirad and
  Guilkey 2013);
* :func:`vibrating_bar`: the first mode of a bar fixed at one end, exact with no body force.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from fempm.materials.neo_hookean import NeoHookean
from fempm.verification.problem import Problem, as_columns
from fempm.verification.vibrating_bar import VibratingBar, vibrating_bar

__all__ = ["PROBLEMS", "AxisAligned", "AxisAligned1D", "GeneralizedVortex", "Problem", "VibratingBar", "axis_aligned",
           "axis_aligned_1d", "generalized_vortex", "vibrating_bar"]


@dataclass(frozen=True)
class AxisAligned1D(Problem):
    r"""1D axis-aligned manufactured solution on :math:`[0, 1]`, both ends fixed:

    .. math::
        u = G \sin(\pi X) \sin(c \pi t), \qquad F = 1 + G\pi \cos(\pi X) \sin(c\pi t),

    1D neo-Hookean :math:`P = \sigma = \mu (F - 1/F)` (:class:`NeoHookean` with
    :math:`\nu = 0`, :math:`\mu = E/2`), :math:`c = \sqrt{E/\rho_0}`. With
    :math:`F_{,X} = -G\pi^2 \sin(\pi X)\sin(c\pi t)` and
    :math:`\ddot u = -G (c\pi)^2 \sin(\pi X) \sin(c\pi t)`:

    .. math::
        b = \ddot u - \frac{\mu}{\rho_0}\Big(1 + \frac{1}{F^2}\Big) F_{,X}.
    """

    G: float = 1e-4
    E: float = 1e7
    rho0: float = 1000.0
    t_end: float = 0.02  # one period, 2 / c

    def __post_init__(self):
        self.declare(name="axis_aligned_1d")

    @property
    def material(self) -> NeoHookean:
        return NeoHookean(self.E, 0.0)

    @property
    def c(self) -> float:
        return float(np.sqrt(self.E / self.rho0))

    def _parts(self, X, t):
        X = as_columns(X, 1)[:, 0]
        w = self.c * np.pi
        return X, w, np.sin(np.pi * X), np.sin(w * t)

    def displacement(self, X, t: float) -> npt.NDArray:
        X, w, s, st = self._parts(X, t)
        return (self.G * s * st)[:, None]

    def velocity(self, X, t: float) -> npt.NDArray:
        X, w, s, st = self._parts(X, t)
        return (self.G * w * s * np.cos(w * t))[:, None]

    def deformation_gradient(self, X, t: float) -> npt.NDArray:
        X, w, s, st = self._parts(X, t)
        return (1.0 + self.G * np.pi * np.cos(np.pi * X) * st)[:, None, None]

    def body_force(self, X, t: float) -> npt.NDArray:
        X, w, s, st = self._parts(X, t)
        F = 1.0 + self.G * np.pi * np.cos(np.pi * X) * st
        dF = -self.G * np.pi**2 * s * st
        mu = self.E / 2.0
        return (-self.G * w**2 * s * st - mu / self.rho0 * (1.0 + 1.0 / F**2) * dF)[:, None]

    def walls(self):
        return [(0, 0.0, "fixed"), (0, 1.0, "fixed")]


@dataclass(frozen=True)
class AxisAligned(Problem):
    r"""Wallstedt and Guilkey's axis-aligned displacement on the unit square (cube):

    .. math::
        u_a = A \sin(\pi X_a) \sin(c\pi t + \varphi_a), \qquad \varphi_a = 2\pi a / 3,

    compressible neo-Hookean :math:`P = \mu (F - F^{-T}) + \lambda \ln J\, F^{-T}`,
    :math:`c = \sqrt{E/\rho_0}`. :math:`F = \operatorname{diag}(F_a)` with
    :math:`F_a = 1 + A\pi \cos(\pi X_a)\sin(c\pi t + \varphi_a)` depending on :math:`X_a` only,
    so :math:`P` is diagonal, :math:`P_{aa} = \mu (F_a - 1/F_a) + \lambda \ln J / F_a`, and
    with :math:`\partial_a \ln J = F_{a,a} / F_a`:
    .. math::
        (\operatorname{Div} P)_a = \partial_a P_{aa}
        = F_{a,a} \Big[\mu \Big(1 + \frac{1}{F_a^2}\Big) + \lambda \frac{1 - \ln J}{F_a^2}\Big],
        \qquad F_{a,a} = -A\pi^2 \sin(\pi X_a) \sin(c\pi t + \varphi_a).

    Particles start at :math:`X + u(X, 0)`; the walls :math:`X_a \in \{0, 1\}` are slip walls
    normal to axis :math:`a` (:math:`u_a = 0` there).
    """

    A: float = 0.05
    dimension: int = 2
    E: float = 1e4
    nu: float = 0.3
    rho0: float = 1.0
    t_end: float = 0.02  # one period, 2 / c

    def __post_init__(self):
        if self.dimension not in (2, 3):
            raise ValueError(f"axis_aligned needs dim 2 or 3, got {self.dimension}")
        self.declare(name=f"axis_aligned_{self.dimension}d", dim=self.dimension, start_displaced=True)

    @property
    def material(self) -> NeoHookean:
        return NeoHookean(self.E, self.nu)

    @property
    def c(self) -> float:
        return float(np.sqrt(self.E / self.rho0))

    def _phase(self, t: float) -> npt.NDArray:
        return self.c * np.pi * t + 2.0 * np.pi * np.arange(self.dim) / 3.0

    def displacement(self, X, t: float) -> npt.NDArray:
        X = as_columns(X, self.dim)
        return self.A * np.sin(np.pi * X) * np.sin(self._phase(t))

    def velocity(self, X, t: float) -> npt.NDArray:
        X = as_columns(X, self.dim)
        return self.A * self.c * np.pi * np.sin(np.pi * X) * np.cos(self._phase(t))

    def _stretches(self, X, t):
        return 1.0 + self.A * np.pi * np.cos(np.pi * X) * np.sin(self._phase(t))

    def deformation_gradient(self, X, t: float) -> npt.NDArray:
        X = as_columns(X, self.dim)
        Fa = self._stretches(X, t)
        return Fa[:, :, None] * np.eye(self.dim)[None]

    def body_force(self, X, t: float) -> npt.NDArray:
        X = as_columns(X, self.dim)
        ph = self._phase(t)
        Fa = self._stretches(X, t)
        dF = -self.A * np.pi**2 * np.sin(np.pi * X) * np.sin(ph)
        lam, mu = self.material.lame
        lnJ = np.log(np.prod(Fa, axis=1))[:, None]
        div_P = dF * (mu * (1.0 + 1.0 / Fa**2) + lam * (1.0 - lnJ) / Fa**2)
        acc = -self.A * (self.c * np.pi) ** 2 * np.sin(np.pi * X) * np.sin(ph)
        return acc - div_P / self.rho0

    def walls(self):
        return [(a, v, "slip") for a in range(self.dim) for v in (0.0, 1.0)]


@dataclass(frozen=True)
class GeneralizedVortex(Problem):
    r"""Generalized vortex (Kamojjala, Brannon, Sadeghirad and Guilkey 2013): the annulus
    :math:`R_0 < R < R_1` (0.75, 1.25) turns by :math:`\alpha(R, t) = g(t) h(R)`,

    .. math::
        h(R) = 1 - 32 (R - 1)^2 + 256 (R - 1)^4, \qquad g(t) = A \sin(\pi t / T),

    :math:`x = R\, e_r(\Theta + \alpha)`. With :math:`\gamma = R \alpha_{,R} = R g h'`,
    :math:`F = e_r \otimes E_R + e_\theta \otimes E_\Theta + \gamma\, e_\theta \otimes E_R`, so
    :math:`J = 1` and the neo-Hookean Cauchy stress is :math:`\sigma = \mu (B - I)`:
    :math:`\sigma_{rr} = 0`, :math:`\sigma_{r\theta} = \mu\gamma`,
    :math:`\sigma_{\theta\theta} = \mu\gamma^2`, functions of :math:`r = R` only. In polar
    coordinates :math:`\operatorname{div}\sigma = -\mu\gamma^2/r\, e_r + \mu(\gamma_{,r} +
    2\gamma/r)\, e_\theta` (and :math:`\operatorname{Div} P = J \operatorname{div}\sigma`), the
    acceleration is :math:`\ddot x = -R \dot\alpha^2 e_r + R \ddot\alpha\, e_\theta`, hence

    .. math::
        b = \Big(-R g'^2 h^2 + \frac{\mu \gamma^2}{\rho_0 R}\Big) e_r
          + \Big(R g'' h - \frac{\mu}{\rho_0}\big(g (h' + R h'') + 2 g h'\big)\Big) e_\theta .

    :math:`h = h' = 0` at both radii: the rims do not move and are traction free. The
    background is the square :math:`[-1.5, 1.5]^2`; no grid conditions.
    """

    A: float = 1.0
    T: float = 1.0
    E: float = 1000.0
    nu: float = 0.3
    rho0: float = 1000.0
    r_in: float = 0.75
    r_out: float = 1.25
    half_width: float = 1.5

    def __post_init__(self):
        self.declare(name="generalized_vortex", dim=2)

    @property
    def t_end(self) -> float:
        return self.T

    @property
    def material(self) -> NeoHookean:
        return NeoHookean(self.E, self.nu)

    @property
    def lower(self):
        return (-self.r_out, -self.r_out)

    @property
    def upper(self):
        return (self.r_out, self.r_out)

    def background(self, h: float):
        return (-self.half_width,) * 2, (self.half_width,) * 2

    def contains(self, X):
        R = np.hypot(*as_columns(X, 2).T)
        return (R >= self.r_in) & (R <= self.r_out)

    @staticmethod
    def _h(R):
        s = R - 1.0
        return 1.0 - 32.0 * s**2 + 256.0 * s**4, -64.0 * s + 1024.0 * s**3, -64.0 + 3072.0 * s**2

    def _g(self, t: float):
        w = np.pi / self.T
        return self.A * np.sin(w * t), self.A * w * np.cos(w * t), -self.A * w**2 * np.sin(w * t)

    def _polar(self, X, t):
        X = as_columns(X, 2)
        R = np.hypot(X[:, 0], X[:, 1])
        theta = np.arctan2(X[:, 1], X[:, 0]) + self._g(t)[0] * self._h(R)[0]
        er = np.column_stack([np.cos(theta), np.sin(theta)])
        et = np.column_stack([-np.sin(theta), np.cos(theta)])
        return X, R, er, et

    def displacement(self, X, t: float) -> npt.NDArray:
        X, R, er, _ = self._polar(X, t)
        return R[:, None] * er - X

    def velocity(self, X, t: float) -> npt.NDArray:
        X, R, _, et = self._polar(X, t)
        return (R * self._g(t)[1] * self._h(R)[0])[:, None] * et

    def deformation_gradient(self, X, t: float) -> npt.NDArray:
        X, R, er, et = self._polar(X, t)
        ER = X / R[:, None]
        ET = np.column_stack([-ER[:, 1], ER[:, 0]])
        gamma = R * self._g(t)[0] * self._h(R)[1]
        return (np.einsum("ni,nj->nij", er, ER) + np.einsum("ni,nj->nij", et, ET)
                + gamma[:, None, None] * np.einsum("ni,nj->nij", et, ER))

    def body_force(self, X, t: float) -> npt.NDArray:
        X, R, er, et = self._polar(X, t)
        g, dg, ddg = self._g(t)
        h, dh, ddh = self._h(R)
        mu = self.material.lame[1]
        gamma = R * g * dh
        b_r = -R * (dg * h) ** 2 + mu * gamma**2 / (self.rho0 * R)
        b_t = R * ddg * h - mu / self.rho0 * (g * (dh + R * ddh) + 2.0 * g * dh)
        return b_r[:, None] * er + b_t[:, None] * et


def axis_aligned_1d(G: float = 1e-4, **kwargs) -> AxisAligned1D:
    """1D axis-aligned solution of amplitude ``G`` (E = 1e7, nu = 0, rho0 = 1000, c = 100)."""
    return AxisAligned1D(G=G, **kwargs)


def axis_aligned(A: float = 0.05, dim: int = 2, **kwargs) -> AxisAligned:
    """Wallstedt and Guilkey's axis-aligned solution of amplitude ``A`` in ``dim`` = 2 or 3
    (E = 1e4, nu = 0.3, rho0 = 1, c = 100)."""
    return AxisAligned(A=A, dimension=dim, **kwargs)


def generalized_vortex(A: float = 1.0, **kwargs) -> GeneralizedVortex:
    """Generalized vortex of amplitude ``A`` (E = 1000, nu = 0.3, rho0 = 1000, T = 1)."""
    return GeneralizedVortex(A=A, **kwargs)


PROBLEMS = {"axis_aligned_1d": axis_aligned_1d, "axis_aligned": axis_aligned,
            "generalized_vortex": generalized_vortex, "vibrating_bar": vibrating_bar}
