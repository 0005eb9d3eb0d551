r"""Patches: the connected sets of marked nodes of a mesh, over all ranks.

Where a body touches a wall or a rigid body, the nodes it touches fall into one patch per place
of contact: two marked dofs are neighbours when a cell holds both. A wall
(:class:`fempm.boundary.Friction`) or a rigid body (:func:`fempm.stepping.contact.correct`) shares the
normal momentum it takes over each patch; :class:`Patches` finds the patches and sums values
over them,

.. math::
    S_i = \sum_{j \in T(i)} s_j,

with :math:`T(i)` the patch of the marked dof :math:`i` and each dof counted once, at the rank
that owns it; :func:`depth_shares` gives each node its share of the patch's normal momentum.
The patches are found anew at every call (one ``allgather`` of the marked dofs, their values
and the pairs of them that share a cell), by label propagation over those pairs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import dolfinx.common
import dolfinx.fem
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

__all__ = ["Patches", "components", "depth_shares"]


@dataclass(frozen=True)
class Patches:
    """The dofs of ``index_map`` (owned and ghost) joined by the cells ``cell_dofs`` (cells,
    dofs per cell; local dofs): the cells that can hold two marked dofs."""

    comm: MPI.Comm
    index_map: dolfinx.common.IndexMap
    cell_dofs: npt.NDArray[np.int32]

    @classmethod
    def of_space(cls, V: dolfinx.fem.FunctionSpace, dofs: npt.NDArray[np.int32] | None = None,
                 index_map: dolfinx.common.IndexMap | None = None) -> Patches:
        """The patches of the (block) dofs of ``V``, over its cells; with ``dofs`` only the
        cells holding two or more of them (the dofs of a wall, which alone can be marked).
        ``index_map``: V's own, or one that extends it by further ghosts."""
        cell_dofs = np.asarray(V.dofmap.list)
        if dofs is not None:
            on = np.isin(cell_dofs, dofs)
            cell_dofs = cell_dofs[np.count_nonzero(on, axis=1) >= 2]
        return cls(V.mesh.comm, V.dofmap.index_map if index_map is None else index_map, cell_dofs)

    def _pairs(self, dofs: npt.NDArray) -> npt.NDArray[np.int64]:
        """The pairs of ``dofs`` that share a cell (global indices, each row sorted)."""
        n = self.index_map.size_local + self.index_map.num_ghosts
        mark = np.zeros(n, dtype=np.bool_)
        mark[dofs] = True
        on = mark[self.cell_dofs]
        cells = np.count_nonzero(on, axis=1) >= 2
        cd, on = self.cell_dofs[cells], on[cells]
        k = cd.shape[1]
        pairs = [np.zeros((0, 2), dtype=np.int32)]
        for a in range(k):
            for b in range(a + 1, k):
                both = on[:, a] & on[:, b]
                pairs.append(np.stack([cd[both, a], cd[both, b]], axis=1))
        local = np.concatenate(pairs).astype(np.int32)
        glob = np.asarray(self.index_map.local_to_global(local.ravel()), dtype=np.int64).reshape(-1, 2)
        return np.sort(glob, axis=1)

    def sums(self, dofs: npt.NDArray, values: npt.NDArray) -> npt.NDArray:
        """For each of the marked local ``dofs`` (distinct, owned or ghost): the sums of
        ``values`` (len(dofs), k) over its patch (each dof counted once, at its owner); 0 for a
        ghost whose owner did not mark it. Collective."""
        dofs = np.asarray(dofs, dtype=np.int32)
        values = np.asarray(values, dtype=np.float64)
        glob = np.asarray(self.index_map.local_to_global(dofs), dtype=np.int64)
        mine = dofs < self.index_map.size_local
        gathered = self.comm.allgather((self._pairs(dofs), glob[mine], values[mine]))
        nodes = np.concatenate([g for _, g, _ in gathered])
        order = np.argsort(nodes, kind="stable")
        nodes = nodes[order]
        vals = np.concatenate([v for _, _, v in gathered]).reshape(-1, values.shape[1])[order]
        out = np.zeros_like(values)
        if len(nodes) == 0:
            return out
        edges = np.concatenate([e for e, _, _ in gathered])
        edges = edges[np.isin(edges, nodes).all(axis=1)]  # a ghost marked where its owner is not
        ends = np.searchsorted(nodes, edges)
        label = components(len(nodes), ends[:, 0], ends[:, 1])
        totals = np.zeros((len(nodes), values.shape[1]))
        np.add.at(totals, label, vals)
        pos = np.minimum(np.searchsorted(nodes, glob), len(nodes) - 1)
        found = nodes[pos] == glob
        out[found] = totals[label[pos[found]]]
        return out


def depth_shares(sums: Callable[[npt.NDArray, npt.NDArray], npt.NDArray], dofs: npt.NDArray, mass: npt.NDArray,
                 speed: npt.NDArray, depth: npt.NDArray) -> npt.NDArray:
    r"""The normal velocity each marked node gives up when its patch shares the normal momentum
    :math:`P = \sum_j m_j v_j` by depth,

    .. math::
        \Delta v_i = P\, \frac{\delta_i}{\sum_j m_j \delta_j}

    (sums over the patch; 0 where it has no depth): ``mass`` :math:`m`, ``speed`` :math:`v` (0
    where a node gives none) and ``depth`` :math:`\delta` (0 where a node takes no share) of
    the nodes ``dofs``; ``sums``: :meth:`Patches.sums` or a stand-in. Collective with it."""
    P, W = sums(dofs, np.stack([mass * speed, mass * depth], axis=1)).T
    return np.where(W > 0.0, P * depth / np.where(W > 0.0, W, 1.0), 0.0)


def components(n: int, a: npt.NDArray, b: npt.NDArray) -> npt.NDArray:
    """The connected components of the graph with nodes 0..n-1 and edges (a, b): each node's
    label, the smallest node of its component (label propagation with pointer jumping)."""
    label = np.arange(n)
    while True:
        low = np.minimum(label[a], label[b])
        new = label.copy()
        np.minimum.at(new, a, low)
        np.minimum.at(new, b, low)
        new = new[new]
        if np.array_equal(new, label):
            return label
        label = new
