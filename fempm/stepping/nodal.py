"""Nodal arrays kept for a run, their ghost updates, and what the grid masses of the compiled
passes share (:class:`NodalMass`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import dolfinx.la
import numpy as np

if TYPE_CHECKING:
    pass

__all__ = ["NodalMass", "kept_nodal_array", "sum_ghosts"]


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


class NodalMass:
    """The grid mass of a :class:`fempm.stepping.lumped.PointGrid`: ``stable_factor`` (after
    P2G), ``velocity`` and ``advance`` (the grid update), and the state a resumed run needs
    (none, by default). ``fusable``: the grid may fuse its update into one pass over the dofs."""

    fusable = False

    def __init__(self, grid):
        self.grid = grid

    def lumped(self, nodal: np.ndarray) -> np.ndarray:
        r"""The lumped masses :math:`\sum_p M_p N_{ip}` (owned + ghost dofs) of the step's P2G
        ``nodal`` array (its mass column)."""
        return nodal[:, 0]

    def checkpoint_state(self) -> tuple[dict, dict[str, np.ndarray]]:
        """(counters, arrays) a resumed run needs to repeat the next steps bit for bit."""
        return {}, {}

    def restore_state(self, counters: dict, arrays: dict[str, np.ndarray]) -> None:
        """Restore :meth:`checkpoint_state`."""
