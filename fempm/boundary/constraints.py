"""What the grid conditions of a step constrain, for the mass solves: the fixed dofs, the slip
components of axis-aligned walls and the dofs of frictional walls."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from fempm.boundary.walls import Fixed, Friction, Slip

__all__ = ["axis_slip_dofs", "fixed_dofs", "friction_dofs"]


def fixed_dofs(bcs: Sequence) -> npt.NDArray[np.int32] | None:
    """The dofs of the :class:`~fempm.boundary.walls.Fixed` conditions (sorted), None if none."""
    fixed = [bc.dofs for bc in bcs if isinstance(bc, Fixed)]
    return np.unique(np.concatenate(fixed)) if fixed else None


def axis_slip_dofs(bcs: Sequence, d: int) -> list[npt.NDArray[np.int32]] | None:
    """Per velocity component a, the dofs of slip walls normal to axis a (None if there are
    none): the consistent solves hold that component at 0 (a constrained fit) rather than
    zeroing it afterwards."""
    comps: list[list] = [[] for _ in range(d)]
    for bc in bcs:
        n = np.asarray(getattr(bc, "normal", np.zeros(0)))
        if isinstance(bc, Slip) and n.shape == (d,) and np.count_nonzero(np.abs(n) > 1e-14) == 1:
            comps[int(np.argmax(np.abs(n)))].append(bc.dofs)
    if not any(comps):
        return None
    return [np.unique(np.concatenate(c)).astype(np.int32) if c else np.zeros(0, dtype=np.int32) for c in comps]


def friction_dofs(bcs: Sequence, num_dofs: int) -> npt.NDArray[np.bool_] | None:
    """A mask of the ``num_dofs`` (owned + ghost) dofs of the walls with Coulomb friction
    (mu > 0), None if there are none.

    Note:
        With consistent mass (and FMPM) the rows of these dofs are lumped. Coulomb friction
        acts node by node on each node's tangential velocity, and the consistently solved
        velocities of a wall's nodes oscillate from node to node, so that some fall below mu
        times their normal velocity change and the friction there is cut short
        (docs/contact.md, "The sliding block").
    """
    mask = np.zeros(num_dofs, dtype=np.bool_)
    for bc in bcs:
        if isinstance(bc, Friction) and bc.mu > 0.0:
            mask[bc.dofs] = True
    return mask if mask.any() else None
