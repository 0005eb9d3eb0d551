r"""Mass models: how the grid solves the P2G sums for nodal values, parsed once from the mass
option into an object.

* :class:`Lumped`: the row sums :math:`m_i = \sum_p M_p \langle N_i \rangle_p`,
  :math:`F_i = b_i / m_i` (a non-negative basis: P1/Q1 or Bernstein);
* :class:`Consistent`: the matrix :math:`m_{ij} = \sum_p M_p \langle N_i N_j \rangle_p`
  assembled and solved with PETSc (the exact projection);
* :class:`FMPM`: the first k terms of the series of :math:`m^{-1}`-preconditioned corrections
  that sums to the consistent solve (:mod:`fempm.transfer.fmpm`), matrix-free.

Each makes its grid solve for the projection (:meth:`MassModel.grid_solve`,
:mod:`fempm.transfer.grid_solves`), and knows its label in tables and its factor on the explicit
stable step (:meth:`MassModel.stable_factor`):
with the lumped step :math:`\Delta t_L`, the consistent mass allows
:math:`\Delta t_L \sqrt{0.8\, \lambda_{min}(M_L^{-1} M_C)}` (the Lanczos estimate lies above
the true value) and FMPM(k) :math:`\Delta t_L / \sqrt{k}`
(:math:`\|M_k^{-1} m\| \le k`).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from fempm.transfer.basis import ParticleBasis
from fempm.transfer.grid_solves import FMPMSolve, GridSolve, LumpedSolve, MatrixSolve

__all__ = ["FMPM", "MASS_RATIO_ITERATIONS", "MASS_RATIO_SAFETY", "MAX_ORDER", "Consistent", "Lumped", "MassModel",
           "mass_model"]

#: largest FMPM order accepted (beyond it the series gains nothing the consistent solve lacks)
MAX_ORDER = 10
#: consistent mass: CG steps of the lambda_min(M_L^-1 M_C) estimate, and the factor on it
MASS_RATIO_ITERATIONS = 30
MASS_RATIO_SAFETY = 0.8


@dataclass(frozen=True)
class MassModel:
    """A grid mass. Subclasses set the class attributes and :meth:`stable_factor`.

    Attributes:
        name: the option's name ("lumped", "consistent", "fmpm").
        matrix: whether a mass matrix is assembled and solved with PETSc.
        couples_dofs: whether the solve couples dofs (rows that ``lump_below`` and friction
            can lump); False for the lumped mass, whose rows are already lumped.
    """

    name: ClassVar[str] = ""
    matrix: ClassVar[bool] = False
    couples_dofs: ClassVar[bool] = True

    @property
    def label(self) -> str:
        """The model's name in tables and messages."""
        return self.name

    @property
    def order(self) -> int:
        """The FMPM order (0 for the other models)."""
        return 0

    def stable_factor(self, ratio_min: Callable[[], float]) -> float:
        """The factor on the lumped-mass stable step; ``ratio_min`` computes
        :math:`\\lambda_{min}(M_L^{-1} M_C)` when the model needs it (collective)."""
        raise NotImplementedError

    def grid_solve(self, basis: ParticleBasis, weights: npt.NDArray, particles, weight: str,
                   given_weights: bool) -> GridSolve:
        """The solve of :math:`m F = b` for a projection with these particle ``weights``
        (``weight``: their kind, "mass" or "volume"; ``given_weights``: given per particle)."""
        raise NotImplementedError


@dataclass(frozen=True)
class Lumped(MassModel):
    """The lumped (row-sum) mass."""

    name: ClassVar[str] = "lumped"
    couples_dofs: ClassVar[bool] = False

    def stable_factor(self, ratio_min: Callable[[], float]) -> float:
        return 1.0

    def grid_solve(self, basis, weights, particles, weight, given_weights):
        return LumpedSolve(basis, weights, self.label)


@dataclass(frozen=True)
class Consistent(MassModel):
    """The consistent mass matrix, solved with a PETSc KSP."""

    name: ClassVar[str] = "consistent"
    matrix: ClassVar[bool] = True

    def stable_factor(self, ratio_min: Callable[[], float]) -> float:
        return float(np.sqrt(MASS_RATIO_SAFETY * ratio_min()))

    def grid_solve(self, basis, weights, particles, weight, given_weights):
        return MatrixSolve(basis, weights, self.label, particles, weight, given_weights)


@dataclass(frozen=True)
class FMPM(MassModel):
    """FMPM(k): k Richardson steps towards the consistent solve from the lumped one."""

    k: int = 5
    name: ClassVar[str] = "fmpm"

    def __post_init__(self):
        if isinstance(self.k, bool) or not isinstance(self.k, (int, np.integer)) or not 1 <= self.k <= MAX_ORDER:
            raise ValueError(f"FMPM order {self.k!r} must be an integer in 1 ... {MAX_ORDER}")

    @property
    def label(self) -> str:
        return f"fmpm{self.k}"

    @property
    def order(self) -> int:
        return self.k

    def stable_factor(self, ratio_min: Callable[[], float]) -> float:
        return 1.0 / float(np.sqrt(self.k))

    def grid_solve(self, basis, weights, particles, weight, given_weights):
        return FMPMSolve(basis, weights, self.label, self.k)


def mass_model(mass: str | MassModel, fmpm_order: int | None = None) -> MassModel:
    """The mass model of an option: a :class:`MassModel`, or ``"lumped"``, ``"consistent"``,
    ``"fmpm"`` (with ``fmpm_order``, default 5), ``"fmpm3"`` or ``"fmpm(3)"``.

    Raises:
        ValueError: an unknown name or an order outside 1 ... :data:`MAX_ORDER`.
    """
    if isinstance(mass, MassModel):
        return mass
    if mass == "lumped":
        return Lumped()
    if mass == "consistent":
        return Consistent()
    m = re.fullmatch(r"fmpm(?:\((\d+)\)|(\d+))?", str(mass))
    if m is None:
        raise ValueError(f"unknown option mass={mass!r}; expected lumped, consistent, fmpm or fmpmK (K = 1 ... {MAX_ORDER})")
    return FMPM(int(m.group(1) or m.group(2) or (fmpm_order if fmpm_order is not None else 5)))
