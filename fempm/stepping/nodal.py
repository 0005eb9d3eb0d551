"""Nodal arrays kept for a run, and their ghost updates."""

from __future__ import annotations

from typing import TYPE_CHECKING

import dolfinx.la
import numpy as np

if TYPE_CHECKING:
    pass

__all__ = ["kept_nodal_array", "sum_ghosts"]


def sum_ghosts(vec) -> None:
    """Ghost contributions of a kept nodal vector to their owners, then the owners' sums back
    to the ghosts (nothing on one rank)."""
    if vec is not None:
        vec.scatter_reverse(dolfinx.la.InsertMode.add)
        vec.scatter_forward()


def kept_nodal_array(index_map, k: int) -> tuple:
    """(vector or None, array): a nodal (owned + ghost dofs, k) array kept for a run; in
    parallel the array of a DOLFINx vector, so that the ghost updates need no copy."""
    n = index_map.size_local + index_map.num_ghosts
    if index_map.comm.size == 1 and index_map.num_ghosts == 0:
        return None, np.empty((n, k))
    vec = dolfinx.la.vector(index_map, bs=k)
    return vec, vec.array.reshape(n, k)
