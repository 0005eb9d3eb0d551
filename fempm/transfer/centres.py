"""The nodal centres of mass of a step, for conditions that check contact by position."""

from __future__ import annotations

from typing import NamedTuple

import numpy.typing as npt

__all__ = ["NodalCentres"]


class NodalCentres(NamedTuple):
    r"""What a wall that checks contact by position needs of the step: the nodal centres of mass
    :math:`\bar x_i = \sum_p M_p N_{ip} x_p / m_i` (dofs, d; NaN where :math:`m_i = 0`) and the
    nodal masses :math:`m_i = \sum_p M_p N_{ip}` (dofs,), on owned and ghost dofs."""

    centre: npt.NDArray
    mass: npt.NDArray
