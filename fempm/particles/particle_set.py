"""Particles: a struct of arrays on a DOLFINx mesh.

Each rank holds the particles inside its owned cells: position ``x`` (n, gdim), ``mass`` and
``volume`` (n,), a global ``ids`` array, the owning local cell ``cells`` and the reference
coordinates ``X`` (n, tdim) in that cell, plus named per-particle ``fields`` (velocity,
deformation gradient, stress, history, user data) that move with the particles between ranks.
"""

from __future__ import annotations

import logging
from typing import Literal

import dolfinx
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.abort import raise_together
from fempm.particles.location import CellLocator, OutsideMeshError, outside_message
from fempm.particles.migration import distribute, migrate, with_room
from fempm.timings import timed

__all__ = ["OutsidePolicy", "Particles"]

log = logging.getLogger("fempm")

OutsidePolicy = Literal["raise", "remove"]
_OUTSIDE = ("raise", "remove")


def _check_positive(name: str, a: npt.NDArray, comm: MPI.Comm) -> None:
    bad = np.flatnonzero(~((a > 0) & (a < np.inf)))  # catches NaN and inf too
    nbad = comm.allreduce(len(bad))
    if nbad:
        raise ValueError(
            f"{nbad} particle(s) have non-positive or non-finite {name} "
            f"(e.g. {name}[{bad[0] if len(bad) else '...'}] = {a[bad[0]] if len(bad) else '...'})"
        )


def repeated_ids(ids: npt.NDArray, comm: MPI.Comm, most: int = 5) -> list[int]:
    """The smallest ``most`` ids that occur more than once over all ranks (collective). Each id
    goes to the rank ``id mod size`` (one all-to-all), which checks its share: memory and time
    of the ids of one rank, not of all (a gather of every id would hold 8 bytes a particle of
    the whole run on every rank)."""
    ids = np.asarray(ids, dtype=np.int64).reshape(-1)
    if comm.size == 1:
        values, counts = np.unique(ids, return_counts=True)
        return values[counts > 1][:most].tolist()
    dest = ids % comm.size
    order = np.argsort(dest, kind="stable")
    sent = np.bincount(dest, minlength=comm.size).astype(np.int64)
    got = np.empty(comm.size, dtype=np.int64)
    comm.Alltoall(sent, got)
    mine = np.empty(int(got.sum()), dtype=np.int64)
    comm.Alltoallv([np.ascontiguousarray(ids[order]), sent], [mine, got])
    values, counts = np.unique(mine, return_counts=True)
    found = np.concatenate(comm.allgather(values[counts > 1][:most]))
    return sorted(found.tolist())[:most]


def _arrays(x, mass, volume, ids, fields, gdim: int):
    """(x, mass, volume) of one rank's arguments as arrays, their shapes checked (this rank's)."""
    x = np.asarray(x, dtype=np.float64).reshape(-1, np.shape(x)[-1] if np.ndim(x) > 1 else 1)
    if x.shape[1] < gdim or np.any(x[:, gdim:] != 0):
        raise ValueError(f"positions must have {gdim} coordinates (extra columns must be 0)")
    x = np.ascontiguousarray(x[:, :gdim])
    n = len(x)
    for name, a in (("mass", mass), ("volume", volume)):
        if np.ndim(a) > 1 or (np.ndim(a) == 1 and np.size(a) != n):
            raise ValueError(f"{name} has shape {np.shape(a)} for {n} particles: give one value or one per particle")
    if ids is not None:
        ids = np.asarray(ids).reshape(-1)
        if len(ids) != n or not np.issubdtype(ids.dtype, np.integer):
            raise ValueError(f"ids must be {n} integers, one per particle (got {len(ids)} of type {ids.dtype})")
    for k, v in (fields or {}).items():
        if len(np.asarray(v)) != n:
            raise ValueError(f"field {k!r} has {len(np.asarray(v))} rows for {n} particles")
    mass = np.broadcast_to(np.asarray(mass, dtype=np.float64), (n,)).copy()
    volume = np.broadcast_to(np.asarray(volume, dtype=np.float64), (n,)).copy()
    return x, mass, volume


class Particles:
    """Particles distributed over the ranks that own the cells containing them: a struct of
    arrays (positions ``x``, cells, reference coordinates ``X``, ``mass``, ``volume``, ids and
    the ``fields`` dictionary), each rank holding its own.

    Args:
        mesh: The background mesh.
        x: Positions (n, gdim) (3 columns accepted); each rank may pass any subset of the
            particles, or none.
        mass: Masses (n,), positive.
        volume: Volumes (n,), positive.
        fields: Extra per-particle arrays (first dimension n), carried along.
        ids: Global integer ids; default: consecutive over the ranks in rank order.
        outside: ``"raise"`` (default): an :class:`OutsideMeshError` names the particles
            outside the mesh; ``"remove"``: drop them (the global count in :attr:`removed` and
            in the log).
        locator: A :class:`fempm.particles.location.CellLocator` of ``mesh`` to reuse.

    Raises:
        ValueError: Arrays of the wrong shapes, masses or volumes not positive, ids repeated.
        OutsideMeshError: Particles outside the mesh with ``outside="raise"``.

    Note:
        Collective: every particle ends on the rank owning its cell.
    """

    @timed("particles_s")
    def __init__(
        self,
        mesh: dolfinx.mesh.Mesh,
        x: npt.ArrayLike,
        mass: npt.ArrayLike,
        volume: npt.ArrayLike,
        *,
        fields: dict[str, npt.ArrayLike] | None = None,
        ids: npt.ArrayLike | None = None,
        outside: OutsidePolicy = "raise",
        locator: CellLocator | None = None,
    ):
        self.mesh = mesh
        self.locator = locator if locator is not None else CellLocator(mesh)
        gdim = mesh.geometry.dim
        comm = mesh.comm
        error = None
        try:  # the shapes each rank was given: an error on one rank is raised on every rank
            x, mass, volume = _arrays(x, mass, volume, ids, fields, gdim)
        except (ValueError, TypeError) as e:
            error = e
        raise_together(comm, error)
        n = len(x)
        nonfinite = comm.allreduce(int(np.count_nonzero(~np.isfinite(x).all(axis=1))))
        if nonfinite:
            raise ValueError(f"{nonfinite} particle position(s) are not finite")
        _check_positive("mass", mass, comm)
        _check_positive("volume", volume, comm)
        if ids is None:
            ids = comm.exscan(n) or 0
            ids = np.arange(ids, ids + n, dtype=np.int64)
        else:
            ids = np.asarray(ids).reshape(-1)
            repeated = repeated_ids(ids, comm)
            if repeated:
                raise ValueError(f"particle ids must be unique over all ranks; repeated: {repeated}")
        data = {"mass": mass, "volume": volume, "ids": np.asarray(ids, dtype=np.int64)}
        for k, v in (fields or {}).items():
            data["field:" + k] = np.asarray(v)
        self._assign(distribute(self.locator, x, data), outside)
        if locator is None:  # runs relocate to neighbouring cells: the tree comes back if a search needs it
            self.locator.release_tree()

    # -- construction helpers -----------------------------------------------------------------
    @classmethod
    def from_located(
        cls,
        locator: CellLocator,
        x: npt.NDArray,
        cells: npt.NDArray[np.int32],
        X: npt.NDArray,
        mass: npt.NDArray,
        volume: npt.NDArray,
        ids: npt.NDArray[np.int64],
        fields: dict[str, npt.NDArray] | None = None,
    ) -> Particles:
        """Particles already in owned cells with known reference coordinates (no search)."""
        self = cls.__new__(cls)
        self.mesh, self.locator = locator.mesh, locator
        self.x, self.cells, self.X = x, np.asarray(cells, dtype=np.int32), X
        self.mass, self.volume, self.ids = mass, volume, ids
        self.fields = dict(fields or {})
        self.removed = 0
        _check_positive("mass", mass, locator.mesh.comm)
        _check_positive("volume", volume, locator.mesh.comm)
        return self

    def _check_outside(self, outside_x: npt.NDArray, outside: OutsidePolicy) -> None:
        """Apply the ``outside`` policy to the positions found in no cell of any rank
        (collective): raise, or log and count them in :attr:`removed`."""
        if outside not in _OUTSIDE:
            raise ValueError(f"unknown option outside={outside!r}; expected one of {_OUTSIDE}")
        comm = self.mesh.comm
        nout = comm.allreduce(len(outside_x))
        if nout and outside == "raise":
            examples = np.concatenate(comm.allgather(outside_x[:5]))
            raise OutsideMeshError(outside_message(nout, examples))
        if nout:
            # info, not a warning: removal is asked for, and fempm.stepping.outside accounts it
            log.info("fempm: removed %d particle(s) outside the mesh", nout)
        self.removed = nout

    def _assign(self, d, outside: OutsidePolicy) -> None:
        self._check_outside(d.outside, outside)
        self.set_arrays({"x": d.x, "cells": d.cells, "X": d.X, **d.data})

    def set_arrays(self, arrays: dict[str, npt.NDArray]) -> None:
        """Positions, cells, reference coordinates and the :meth:`data_arrays` data, by name."""
        self.x, self.cells, self.X = arrays["x"], arrays["cells"], arrays["X"]
        self.mass, self.volume, self.ids = arrays["mass"], arrays["volume"], arrays["ids"]
        self.fields = {k[6:]: v for k, v in arrays.items() if k.startswith("field:")}

    def data_arrays(self) -> dict[str, npt.NDArray]:
        """The per-particle arrays besides positions, cells and reference coordinates, by name:
        ``mass``, ``volume``, ``ids`` and every field as ``field:<name>`` (what migrates and
        what a checkpoint keeps)."""
        data = {"mass": self.mass, "volume": self.volume, "ids": self.ids}
        data.update({"field:" + k: v for k, v in self.fields.items()})
        return data

    def check_fields(self, shapes: dict[str, tuple[int, ...]]) -> None:
        """Every per-particle array has a row per particle, and the fields named in ``shapes``
        have those shapes per particle; else a ValueError naming the field and the shapes
        (collective: raised on every rank when it is wrong on any)."""
        n = len(self.x)
        problem = None
        arrays = {"mass": self.mass, "volume": self.volume, "ids": self.ids,
                  **{f"fields[{k!r}]": v for k, v in self.fields.items()}}
        for name, a in arrays.items():
            a = np.asarray(a)
            key = name[8:-2] if name.startswith("fields[") else None
            want = (n, *shapes[key]) if key in shapes else None
            if (want is not None and a.shape != want) or (want is None and (a.ndim == 0 or len(a) != n)):
                problem = (f"particle {name} has shape {a.shape}, expected "
                           f"{want if want is not None else f'({n}, ...)'} for {n} particles in {self.gdim}D")
                break
        if problem is not None and self.comm.size > 1:
            problem += f" (on rank {self.comm.rank})"
        problems = [q for q in (self.comm.allgather(problem) if self.comm.size > 1 else [problem]) if q]
        if problems:
            raise ValueError(problems[0])

    # -- queries ------------------------------------------------------------------------------
    @property
    def comm(self) -> MPI.Comm:
        return self.mesh.comm

    @property
    def sample_locator(self) -> CellLocator:
        """Locator over owned and ghost cells, for the sample points of particle domains
        (created on first use, then kept)."""
        loc = getattr(self, "_sample_locator", None)
        if loc is None:
            loc = self._sample_locator = CellLocator(self.mesh, tol=self.locator.tol, ghosts=True)
        return loc

    @property
    def gdim(self) -> int:
        return self.mesh.geometry.dim

    def __len__(self) -> int:
        return len(self.x)

    @property
    def num_global(self) -> int:
        """Total number of particles over all ranks (collective)."""
        return self.comm.allreduce(len(self.x))

    def density(self) -> npt.NDArray:
        return self.mass / self.volume

    # -- motion -------------------------------------------------------------------------------
    def relocate(self, outside: OutsidePolicy = "raise", *, left: npt.NDArray[np.bool_] | None = None) -> None:
        """Update cells and reference coordinates after ``x`` changed (collective).

        Each particle's previous cell is tested first; particles that left the rank's owned
        cells move to the rank that owns their new cell. ``left``: the particles that may have
        left their cells, when the caller has already updated ``X`` of all the others (the
        compiled step does, in closed form); only those are searched for.
        """
        ghosts = self.comm.size > 1  # leavers found in a ghost cell go straight to its owner
        searched = None  # the particles searched for (all, when None)
        if left is None:
            previous = self.cells  # relocate returns new arrays
            cells, X = self.locator.relocate(self.x, self.cells, ghosts=ghosts)
        else:  # only the particles searched for can have left the owned cells: O(leavers)
            cells, X = self.cells, self.X
            searched = np.flatnonzero(left)
            previous = cells[searched]  # their cells before the search (a copy)
            if len(searched):
                cells[searched], X[searched] = self.locator.locate_near(self.x[searched], previous, ghosts=ghosts)
        found = cells if searched is None else cells[searched]
        leaving = (found < 0) | (found >= self.locator.num_cells) if ghosts else found < 0
        rows = np.flatnonzero(leaving) if searched is None else searched[leaving]
        previous = previous[leaving]  # the leavers' cells before they moved
        lost = int(np.count_nonzero(cells[rows] < 0))
        counts = np.array([len(rows) - lost, lost])  # in a ghost cell, in none here
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, counts, op=MPI.SUM)
        self.removed = 0
        if not counts.any():
            self.cells, self.X = cells, X
            return
        if outside not in _OUTSIDE:  # before anything moves
            raise ValueError(f"unknown option outside={outside!r}; expected one of {_OUTSIDE}")
        arrays = {"x": self.x, "cells": cells, "X": X, **self.data_arrays()}
        arrays, gone = migrate(self.locator, arrays, rows, previous if ghosts else None,
                               counts=(int(counts[0]), int(counts[1])))  # in place, O(leavers)
        if gone is not None:  # some rank searched beyond its ghost cells
            self._check_outside(gone, outside)
        self.set_arrays(arrays)

    def sort_by_cell(self) -> None:
        """Order the particles by cell (stable), for memory locality in the particle passes.
        The sorted arrays keep spare rows (:func:`fempm.particles.migration.with_room`), so that the
        particles arriving from other ranks over the next steps do not reallocate them."""
        order = np.argsort(self.cells, kind="stable")
        if np.all(order[1:] > order[:-1]):
            return
        for name in ("x", "cells", "X", "mass", "volume", "ids"):  # one array at a time: one temporary
            setattr(self, name, _sorted_with_room(getattr(self, name), order))
        for k in list(self.fields):
            self.fields[k] = _sorted_with_room(self.fields[k], order)


def _sorted_with_room(a: npt.NDArray, order: npt.NDArray) -> npt.NDArray:
    """``a[order]`` as the first rows of an array with spare rows
    (:func:`~fempm.particles.migration.with_room`)."""
    n = len(order)
    room = with_room(n, a)
    np.take(a, order, axis=0, out=room[:n])
    return room[:n]
