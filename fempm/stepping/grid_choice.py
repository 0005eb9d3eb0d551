"""Which grid steps a step state's options: one registry of the grids, tried in order.

Each grid class says why a state's options, space and mesh do not take it (its ``refusal``
classmethod, None where they do) and what it takes (``takes``, for messages). The first grid of
:data:`GRIDS` that the options take, among those for one field or for contact, steps them:

============================================  ========  =======  ==========================
grid                                          compiled  contact  takes
============================================  ========  =======  ==========================
:class:`~fempm.stepping.contact_points.ContactPointGrid`  yes  yes  point particles, lumped, USL/MUSL
:class:`~fempm.stepping.contact.ContactGrid`  no        yes      any
:class:`~fempm.stepping.fbar_grid.FBarPointGrid`  yes  no   as PointGrid, F-bar only
:class:`~fempm.stepping.lumped.PointGrid`     yes       no       point particles, lumped/consistent/FMPM
:class:`~fempm.stepping.domain_grid.DomainGrid`  yes    no       CPDI1/CPDI2/GIMP, lumped/consistent/FMPM, degree 1
:class:`~fempm.stepping.grid.SingleFieldGrid`  no       no       any
============================================  ========  =======  ==========================

A grid steps the ``volumetric`` options of its entry only (F-bar: :class:`~fempm.stepping.fbar_grid.FBarPointGrid`,
the numpy grids). ``compiled=False`` leaves the compiled grids out; ``compiled=True`` where no compiled grid takes
the options is an error that gives each compiled grid's reason.
"""

from __future__ import annotations

from dataclasses import dataclass

from fempm.stepping.contact import ContactGrid
from fempm.stepping.contact_points import ContactPointGrid
from fempm.stepping.domain_grid import DomainGrid
from fempm.stepping.fbar_grid import FBarPointGrid
from fempm.stepping.grid import Grid, SingleFieldGrid
from fempm.stepping.lumped import PointGrid
from fempm.stepping.state import StepState

__all__ = ["GRIDS", "GridEntry", "choose_grid"]


@dataclass(frozen=True)
class GridEntry:
    """A grid of the registry: its class (which gives its ``refusal`` and what it ``takes``),
    whether it runs compiled passes, whether it steps contact (one velocity field per body) and
    the ``StepOptions.volumetric`` it steps (None: any)."""

    grid: type[Grid]
    compiled: bool
    contact: bool
    volumetric: str | None = None


#: the grids, in the order they are tried
GRIDS = (
    GridEntry(ContactPointGrid, compiled=True, contact=True, volumetric="standard"),
    GridEntry(ContactGrid, compiled=False, contact=True),
    GridEntry(FBarPointGrid, compiled=True, contact=False, volumetric="fbar"),
    GridEntry(PointGrid, compiled=True, contact=False, volumetric="standard"),
    GridEntry(DomainGrid, compiled=True, contact=False, volumetric="standard"),
    GridEntry(SingleFieldGrid, compiled=False, contact=False),
)


def choose_grid(state: StepState) -> Grid:
    """The grid for ``state``'s options (see the module), made.

    Raises:
        ValueError: ``compiled=True`` where no compiled grid takes the options (each one's reason
            given).
    """
    transfer = state.options.velocity_transfer
    if state.contact is not None and transfer.name not in ("flip", "pic"):
        raise ValueError(f"contact (one velocity field per body) takes transfer='flip' or 'pic', not {transfer.name!r}")
    state.affine(check=True)  # the particles' affine matrices, made where the transfer carries them
    compiled = state.compiled is not False
    contact = state.contact is not None
    refused = []  # (grid, reason) of the compiled grids passed over
    for entry in GRIDS:
        if entry.contact != contact or (entry.compiled and not compiled):
            continue
        if entry.volumetric not in (None, state.options.volumetric):
            continue
        if not entry.compiled and state.compiled:
            reasons = "; ".join(f"{grid.__name__} ({grid.takes}): {why}" for grid, why in refused)
            raise ValueError(f"compiled=True, but no compiled grid takes these options: {reasons}")
        reason = entry.grid.refusal(state)
        if reason is None:
            return entry.grid(state)
        refused.append((entry.grid, reason))
    raise AssertionError("the generic grids take every option")  # pragma: no cover
