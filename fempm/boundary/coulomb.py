r"""Coulomb friction at grid nodes, shared by the frictional walls
(:class:`fempm.boundary.walls.Friction`) and the contact between bodies
(:func:`fempm.stepping.contact.correct`).

A node's relative velocity :math:`w = w_t + w_n \hat n` (normal part :math:`w_n`, tangential
part :math:`w_t`) gives up :math:`\Delta w_n` of its normal part, and its tangential part
loses at most :math:`\mu \Delta w_n` of its length (it sticks where that is more):

.. math::
    w^+ = w_t \max\Big(0,\ 1 - \mu \frac{\Delta w_n}{|w_t|}\Big) + (w_n - \Delta w_n)\, \hat n .
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["coulomb"]


def coulomb(w_t: npt.NDArray, w_n: npt.NDArray, n: npt.NDArray, dw_n: npt.NDArray, mu: float) -> npt.NDArray:
    r"""The relative velocities after friction, :math:`w^+` (see the module), of nodes with
    tangential parts ``w_t`` (k, d), normal parts ``w_n`` (k,) along the unit normals ``n``
    ((k, d) or (d,)), the normal velocity taken ``dw_n`` (k,) and the coefficient ``mu``."""
    speed = np.linalg.norm(w_t, axis=1)
    sliding = speed > 0
    keep = np.where(sliding, np.maximum(0.0, 1.0 - mu * dw_n / np.where(sliding, speed, 1.0)), 0.0)
    return w_t * keep[:, None] + (w_n - dw_n)[:, None] * n
