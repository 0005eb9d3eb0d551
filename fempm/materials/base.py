"""The material protocol and shared kinematics."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar, Protocol

import numpy as np
import numpy.typing as npt

from fempm.arguments import check_numbers
from fempm.kernels.kinematics import skew, sym  # noqa: F401  (the materials' tensor helpers)

__all__ = ["LAW_ATTRIBUTES", "Internal", "IsotropicElastic", "Material", "check_materials", "identity", "lame", "trace"]


@dataclass(frozen=True)
class Internal:
    """An internal (history) variable of a law: the per-particle field ``name`` of ``shape``
    per particle (-1 stands for the space dimension), starting at ``initial``. The solver
    allocates it in ``particles.fields``, so that it moves with the particles between ranks and
    goes into checkpoints and output frames."""

    name: str
    shape: tuple[int, ...] = ()
    initial: float = 0.0

    def shape_for(self, d: int) -> tuple[int, ...]:
        """The per-particle shape in ``d`` dimensions."""
        return tuple(d if k == -1 else k for k in self.shape)

    def allocate(self, n: int, d: int) -> npt.NDArray:
        return np.full((n, *self.shape_for(d)), float(self.initial))


class Material(Protocol):
    """What the explicit solver needs from a constitutive law (arrays over particles).

    A law with internal variables declares them in ``history`` (:class:`Internal`); its
    ``stress`` then takes a sixth argument ``state``, a dict of those variables of the
    particles (``state[name]`` of shape (n, ...)), and stores their updates in it."""

    history: tuple[Internal, ...]

    def stress(self, F: npt.NDArray, L: npt.NDArray, sigma: npt.NDArray, dt: float, rho: npt.NDArray) -> npt.NDArray:
        """Cauchy stress (n, d, d) after the step, from the deformation gradient ``F``, the
        velocity gradient ``L``, the previous stress and the current density."""

    def wave_speed(self, F: npt.NDArray, rho: npt.NDArray) -> npt.NDArray:
        """Dilatational wave speed (n,)."""

    def energy_density(self, F: npt.NDArray) -> npt.NDArray:
        """Stored energy per reference volume (n,)."""


#: what the solver calls on a law (:class:`Material`)
LAW_ATTRIBUTES = ("stress", "wave_speed", "energy_density", "history")


def check_materials(materials: Sequence) -> None:
    """Each law has what the solver calls (:data:`LAW_ATTRIBUTES`), checked once so that the
    solver reads them without guessing.

    Raises:
        TypeError: A law without one of them, named with its index and class.
    """
    for i, mat in enumerate(materials):
        missing = [a for a in LAW_ATTRIBUTES if not hasattr(mat, a)]
        if missing:
            raise TypeError(f"material {i} ({type(mat).__name__}) lacks {', '.join(missing)}: a law "
                            "(fempm.materials.base.Material) has stress, wave_speed, energy_density and history "
                            "(its internal variables, () for none)")


def lame(E: float, nu: float) -> tuple[float, float]:
    """Lame parameters (lambda, mu) from Young's modulus and Poisson's ratio."""
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


@dataclass(frozen=True)
class IsotropicElastic:
    r"""Young's modulus and Poisson's ratio (checked), the Lame parameters and the dilatational
    wave speed :math:`\sqrt{(\lambda + 2\mu)/\rho}`, shared by the elastic laws."""

    E: float
    nu: float = 0.0
    history: ClassVar[tuple[Internal, ...]] = ()  # a law's internal variables (none: elastic)
    #: the law takes F-bar's averaged deformation (fempm.stepping.fbar): its stress comes from F or L
    volumetric_average: ClassVar[bool] = True

    def __post_init__(self):
        check_numbers(self)  # every numeric parameter of the law (subclasses' too)
        if not (0.0 < self.E < np.inf) or not -1.0 < self.nu < 0.5:  # NaN fails both
            raise ValueError(f"{type(self).__name__} needs E > 0 and -1 < nu < 0.5 (got E={self.E}, nu={self.nu})")

    @property
    def lame(self) -> tuple[float, float]:
        return lame(self.E, self.nu)

    def wave_speed(self, F: npt.NDArray, rho: npt.NDArray) -> npt.NDArray:
        lam, mu = self.lame
        return np.sqrt((lam + 2 * mu) / rho)


def identity(n: int, d: int) -> npt.NDArray:
    return np.broadcast_to(np.eye(d), (n, d, d)).copy()


def trace(A: npt.NDArray) -> npt.NDArray:
    return np.trace(A, axis1=1, axis2=2)
