"""Nodal arrays kept for a run, their ghost updates, what the grid masses of the compiled
passes share (:class:`NodalMass`) and what they read of their grid (:class:`NodalLayout`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import dolfinx.la
import numpy as np
import numpy.typing as npt

from fempm.stepping.state import StepState

__all__ = ["NodalLayout", "NodalMass", "exchanged_rows", "kept_nodal_array", "sum_ghosts"]


def sum_ghosts(vec) -> None:
    """Ghost contributions of a kept nodal vector to their owners, then the owners' sums back
    to the ghosts (nothing on one rank)."""
    if vec is not None:
        vec.scatter_reverse(dolfinx.la.InsertMode.add)
        vec.scatter_forward()


def exchanged_rows(index_map) -> npt.NDArray[np.bool_]:
    """(owned + ghost dofs,) bool: the rows :func:`sum_ghosts` may write, the ghosts and the owned
    dofs that other ranks hold as ghosts (none on one rank). Collective."""
    n = index_map.size_local + index_map.num_ghosts
    if index_map.comm.size == 1 and index_map.num_ghosts == 0:
        return np.zeros(n, dtype=np.bool_)
    vec = dolfinx.la.vector(index_map, bs=1)
    vec.array[:] = 0.0
    vec.array[index_map.size_local:] = 1.0
    vec.scatter_reverse(dolfinx.la.InsertMode.add)  # > 0 on the owned dofs ghosted elsewhere
    out = vec.array > 0.0
    out[index_map.size_local:] = True
    return out


def kept_nodal_array(index_map, k: int) -> tuple:
    """(vector or None, array): a nodal (owned + ghost dofs, k) array kept for a run; in
    parallel the array of a DOLFINx vector, so that the ghost updates need no copy."""
    n = index_map.size_local + index_map.num_ghosts
    if index_map.comm.size == 1 and index_map.num_ghosts == 0:
        return None, np.empty((n, k))
    vec = dolfinx.la.vector(index_map, bs=k)
    return vec, vec.array.reshape(n, k)


@dataclass(frozen=True, eq=False)
class NodalLayout:
    """What a grid mass reads of the compiled grid it serves: the step state, the space's
    layout and the grid's particle pass :math:`M_C y` (a hook, as the state's).

    Attributes:
        state: The step state (particles, options, conditions, record).
        cell: The kernels' cell type (:mod:`fempm.kernels.shape`).
        K: The cells' inverse Jacobians, or the multilinear cells' geometry, of the kernels.
        cell_dofs: The cells' dofs (cells, dofs per cell), int32.
        index_map: The space's dof index map.
        free: The (dof, component) entries solved for, (dofs, d) bool.
        mass_apply: ``mass_apply(y, lump, out)``: :math:`M_C y` without the ``lump`` rows into
            ``out`` on this rank's dofs, ghosts not summed (one particle pass).
        samples: ``samples()``: the step's averaged basis
            (:class:`fempm.kernels.bundles.Samples`) of a grid of particle domains, else None.
    """

    state: StepState
    cell: int
    K: npt.NDArray
    cell_dofs: npt.NDArray
    index_map: object
    free: npt.NDArray
    mass_apply: Callable[[npt.NDArray, npt.NDArray, npt.NDArray], None]
    samples: Callable[[], object] | None = None

    @property
    def d(self) -> int:
        """The geometric dimension."""
        return self.state.particles.gdim

    @property
    def num_dofs(self) -> int:
        """Owned and ghost dofs of this rank."""
        return self.index_map.size_local + self.index_map.num_ghosts

    @property
    def conditions(self):
        """The grid conditions (:class:`fempm.boundary.conditions.GridConditions`)."""
        return self.state.conditions

    @property
    def options(self):
        """The step's options."""
        return self.state.options

    def nodal_array(self, k: int) -> tuple:
        """A nodal (owned + ghost dofs, k) array kept for the run: (vector or None, array)."""
        return kept_nodal_array(self.index_map, k)


class NodalMass:
    """The grid mass of a :class:`fempm.stepping.lumped.PointGrid`, on its :class:`NodalLayout`:
    ``stable_factor`` (after P2G), ``velocity`` and ``advance`` (the grid update), and the state a
    resumed run needs (none, by default). ``fusable``: the grid may fuse its update into one pass
    over the dofs."""

    fusable = False

    def __init__(self, layout: NodalLayout):
        self.layout = layout

    def lumped(self, nodal: np.ndarray) -> np.ndarray:
        r"""The lumped masses :math:`\sum_p M_p N_{ip}` (owned + ghost dofs) of the step's P2G
        ``nodal`` array (its mass column)."""
        return nodal[:, 0]

    def checkpoint_state(self) -> tuple[dict, dict[str, np.ndarray]]:
        """(counters, arrays) a resumed run needs to repeat the next steps bit for bit."""
        return {}, {}

    def restore_state(self, counters: dict, arrays: dict[str, np.ndarray]) -> None:
        """Restore :meth:`checkpoint_state`."""
