"""The material protocol and shared kinematics."""

from __future__ import annotations

from typing import Protocol

import numpy as np
import numpy.typing as npt


class Material(Protocol):
    """What the explicit solver needs from a constitutive law (arrays over particles)."""

    history: tuple[str, ...]

    def stress(self, F: npt.NDArray, L: npt.NDArray, sigma: npt.NDArray, dt: float, rho: npt.NDArray) -> npt.NDArray:
        """Cauchy stress (n, d, d) after the step, from the deformation gradient ``F``, the
        velocity gradient ``L``, the previous stress and the current density."""

    def wave_speed(self, F: npt.NDArray, rho: npt.NDArray) -> npt.NDArray:
        """Dilatational wave speed (n,)."""

    def energy_density(self, F: npt.NDArray) -> npt.NDArray:
        """Stored energy per reference volume (n,)."""


def lame(E: float, nu: float) -> tuple[float, float]:
    """Lame parameters (lambda, mu) from Young's modulus and Poisson's ratio."""
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


def identity(n: int, d: int) -> npt.NDArray:
    return np.broadcast_to(np.eye(d), (n, d, d)).copy()


def sym(A: npt.NDArray) -> npt.NDArray:
    return 0.5 * (A + np.swapaxes(A, 1, 2))


def trace(A: npt.NDArray) -> npt.NDArray:
    return np.trace(A, axis1=1, axis2=2)
