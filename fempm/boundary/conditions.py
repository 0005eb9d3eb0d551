"""The grid conditions of a step as one object: applied to the grid velocity, and what they
constrain in the mass solves (the fixed dofs, the slip components of axis-aligned walls, the
dofs of frictional walls)."""

from __future__ import annotations

from collections.abc import Sequence

import dolfinx.fem
import numpy as np
import numpy.typing as npt

from fempm.boundary.walls import Fixed, Friction, Slip
from fempm.transfer.centres import NodalCentres

__all__ = ["GridConditions"]


class GridConditions:
    """The conditions ``bcs`` on the velocity space ``V``.

    Attributes:
        bcs: the conditions, applied in order.
        fixed_dofs: the dofs of the :class:`~fempm.boundary.walls.Fixed` conditions (sorted),
            None if there are none.
        slip_components: per velocity component a, the dofs of slip walls normal to axis a
            (None if there are none): the consistent solves hold that component at 0 (a
            constrained fit) rather than zeroing it afterwards.
        friction_dofs: a mask of the owned + ghost dofs of walls with Coulomb friction
            (mu > 0), None if there are none. With consistent mass (and FMPM) their rows are
            lumped: Coulomb friction acts node by node on each node's tangential velocity, and
            consistently solved velocities oscillate from node to node along a wall, so that
            some fall below mu times their normal velocity change and the friction there is
            cut short (docs/contact.md, "The sliding block").
        frictional: whether a wall has Coulomb friction (mu > 0), on any rank.
        curved: whether a slip or frictional wall has a normal per node (a tagged wall that is
            not straight), on any rank.
        on_update: the conditions that act on the velocity update of a step only (their
            ``acts_on_update``; e.g. the absorbing dashpots, :class:`~fempm.boundary.absorbing.Dashpot`,
            and the colliders, :class:`~fempm.colliders.grid.ColliderContact`), with their
            ``on_update(v, centroids, dt)``.
        needs_positions: whether a condition checks contact by position or acts by the nodal
            mass (the step then maps the nodal centres of mass and masses,
            :class:`~fempm.transfer.centres.NodalCentres`).
        zero_components: whether every condition only holds velocity components at 0.
        other_kinds: what the conditions that do more than that are (their ``kind``: "a
            frictional wall", "colliders", ...), in order, each once.
        held_dofs: the dofs (owned + ghost, sorted) of the conditions on given nodes (every
            condition but the colliders), None if there are none: where the supports and walls
            take their reactions (:mod:`fempm.stepping.reactions`).
    """

    def __init__(self, V: dolfinx.fem.FunctionSpace, bcs: Sequence = ()):
        self.bcs = tuple(bcs)
        d = V.dofmap.index_map_bs
        index_map = V.dofmap.index_map
        self.num_dofs = index_map.size_local + index_map.num_ghosts
        fixed = [bc.dofs for bc in self.bcs if isinstance(bc, Fixed)]
        self.fixed_dofs = np.unique(np.concatenate(fixed)) if fixed else None
        self.slip_components = _axis_slip_dofs(self.bcs, d)
        mask = np.zeros(self.num_dofs, dtype=np.bool_)
        for bc in self.bcs:
            if isinstance(bc, Friction) and bc.mu > 0.0:
                mask[bc.dofs] = True
        self.friction_dofs = mask if mask.any() else None
        self.frictional = any(isinstance(bc, Friction) and bc.mu > 0.0 for bc in self.bcs)
        self.curved = any(isinstance(bc, (Slip, Friction)) and np.ndim(bc.normal) == 2 for bc in self.bcs)
        self.on_update = tuple(bc for bc in self.bcs if getattr(bc, "acts_on_update", False))
        self.needs_positions = any(bc.needs_positions for bc in self.bcs)
        self.zero_components = all(bc.zero_components for bc in self.bcs)
        held = [bc.dofs for bc in self.bcs if getattr(bc, "dofs", None) is not None]
        self.held_dofs = np.unique(np.concatenate(held)).astype(np.int32) if held else None
        self.other_kinds = tuple(dict.fromkeys(getattr(bc, "kind", type(bc).__name__) for bc in self.bcs
                                               if not bc.zero_components))

    def apply(self, v: npt.NDArray, centroids: NodalCentres | None = None, dt: float | None = None) -> None:
        """Every condition on the grid velocity ``v`` (dofs, d), in place; ``centroids``: the
        step's nodal centres of mass (and masses), for the conditions that check contact by
        position and for those that act by the nodal mass; ``dt``: given when ``v`` is the update
        of a step of that size, on which the conditions of :attr:`on_update` act first (in order)."""
        if dt is not None:
            for bc in self.on_update:
                bc.on_update(v, centroids, dt)
        for bc in self.bcs:
            bc.apply(v, centroids)

    def free(self, d: int) -> npt.NDArray[np.bool_]:
        """(dofs, d): the components solved for (False where fixed or on an axis-aligned slip wall)."""
        free = np.ones((self.num_dofs, d), dtype=np.bool_)
        if self.fixed_dofs is not None:
            free[self.fixed_dofs] = False
        for c, dofs in enumerate(self.slip_components or ()):
            free[dofs, c] = False
        return free

    def fixed_mask(self) -> npt.NDArray[np.bool_]:
        """(dofs,): the dofs of the fixed conditions."""
        fixed = np.zeros(self.num_dofs, dtype=np.bool_)
        if self.fixed_dofs is not None:
            fixed[self.fixed_dofs] = True
        return fixed


def _axis_slip_dofs(bcs: Sequence, d: int) -> list[npt.NDArray[np.int32]] | None:
    comps: list[list] = [[] for _ in range(d)]
    for bc in bcs:
        if isinstance(bc, Slip) and np.shape(bc.normal) == (d,) and bc.axis is not None:
            comps[bc.axis].append(bc.dofs)
    if not any(comps):
        return None
    return [np.unique(np.concatenate(c)).astype(np.int32) if c else np.zeros(0, dtype=np.int32) for c in comps]
