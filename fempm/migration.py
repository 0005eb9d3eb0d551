"""Send particles to the MPI rank that owns the cell containing them.

Points found in an owned cell of the calling rank stay there. The others go, in a first
exchange, to every rank whose bounding box holds them; those ranks test them against their
owned cells and answer. The lowest rank that found a point becomes its owner and receives the
particle's data in a second exchange. Points that no rank contains are returned as *outside*.
Only array slices per rank are exchanged (never per-particle Python objects).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from fempm.location import CellLocator, lowest_finding_rank


@dataclass
class Distributed:
    """Particle data owned by this rank after :func:`distribute`."""

    x: npt.NDArray
    cells: npt.NDArray[np.int32]
    X: npt.NDArray
    data: dict[str, npt.NDArray]
    outside: npt.NDArray  # positions (of points given on this rank) found in no cell


def _take(data: dict[str, npt.NDArray], idx: npt.NDArray) -> dict[str, npt.NDArray]:
    return {k: v[idx] for k, v in data.items()}


def _concat(parts: list[dict[str, npt.NDArray]], like: dict[str, npt.NDArray]):
    return {k: np.concatenate([p[k] for p in parts] + [like[k][:0]]) for k in like}


def distribute(
    locator: CellLocator,
    x: npt.NDArray,
    data: dict[str, npt.NDArray],
    *,
    cells: npt.NDArray[np.int32] | None = None,
    X: npt.NDArray | None = None,
) -> Distributed:
    """Move points ``x`` (with per-point arrays ``data``) to the ranks that own them.

    Collective. ``cells``/``X``, when given, are a location already made on this rank
    (``cells < 0`` for points not found here).
    """
    comm = locator.mesh.comm
    x = np.asarray(x, dtype=np.float64)
    if cells is None:
        cells, X = locator.locate(x)
    here = cells >= 0
    keep_x, keep_c, keep_X = [x[here]], [cells[here]], [X[here]]
    keep_d = [_take(data, here)]
    miss = np.flatnonzero(~here)
    if comm.size == 1:
        return Distributed(x[here], cells[here], X[here], keep_d[0], x[miss])

    size = comm.size
    sent_idx, recv_pts = locator.send_to_candidates(x[miss])  # sent_idx: indices into miss
    found = [locator.locate(p) for p in recv_pts]
    answers = comm.alltoall([c >= 0 for c, _ in found])
    owner = lowest_finding_rank(sent_idx, answers, len(miss))
    claims = []
    for r in range(size):
        pos = np.flatnonzero(owner[sent_idx[r]] == r)  # positions in the batch sent to r
        claims.append((pos, _take(data, miss[sent_idx[r][pos]])))
    received = comm.alltoall(claims)
    for s, (pos, d) in enumerate(received):
        keep_x.append(recv_pts[s][pos])
        keep_c.append(found[s][0][pos])
        keep_X.append(found[s][1][pos])
        keep_d.append(d)
    return Distributed(
        np.concatenate(keep_x),
        np.concatenate(keep_c).astype(np.int32),
        np.concatenate(keep_X),
        _concat(keep_d, data),
        x[miss[owner == size]],
    )


def replace_rows(arrays: dict[str, npt.NDArray], holes: npt.NDArray, arrivals: dict[str, npt.NDArray],
                 slack: float = 0.05) -> dict[str, npt.NDArray]:
    """Remove the rows ``holes`` (ascending) of every array and add the rows of ``arrivals``,
    touching only O(len(holes) + len(arrivals)) rows: arrivals fill the holes, the last rows
    fill the holes left over, and arrays shrink as views. When they grow they take the room
    their base array has beyond them, or are reallocated with ``slack`` spare rows (so that
    particles crossing between ranks every step do not copy every array every step). Row order
    is not kept."""
    if not arrays:
        return arrays
    n = len(next(iter(arrays.values())))
    m = len(next(iter(arrivals.values()))) if arrivals else 0
    h = len(holes)
    n_new = n - h + m
    fill = min(h, m)
    out = {}
    if m <= h:  # shrink: arrivals into the first holes, the last rows into the holes beyond n_new
        rest = holes[fill:]
        inside = rest[rest < n_new]  # holes that must be filled
        tail = np.setdiff1d(np.arange(n_new, n), holes, assume_unique=True)  # rows to move in
        for k, a in arrays.items():
            a[holes[:fill]] = arrivals[k]
            a[inside] = a[tail]
            out[k] = a[:n_new]
        return out
    for k, a in arrays.items():  # grow: arrivals into every hole, the rest appended
        a[holes] = arrivals[k][:fill]
        base = a.base if isinstance(a.base, np.ndarray) else None
        if (base is not None and base.shape[1:] == a.shape[1:] and base.shape[0] >= n_new
                and base.ctypes.data == a.ctypes.data and base.flags.c_contiguous and a.flags.c_contiguous):
            grown = base[:n_new]
        else:
            grown = np.empty((int(n_new * (1 + slack)) + 1, *a.shape[1:]), dtype=a.dtype)
            grown[:n] = a
            grown = grown[:n_new]
        grown[n:] = arrivals[k][fill:]
        out[k] = grown
    return out


def migrate(locator: CellLocator, arrays: dict[str, npt.NDArray], leaving: npt.NDArray) -> tuple[dict, npt.NDArray]:
    """Send the particles ``leaving`` (indices, ascending; their cells are not owned here) to
    the ranks that own their cells and take in the particles the other ranks send here, in
    place (:func:`replace_rows`). ``arrays`` holds ``x``, ``cells``, ``X`` and the particle
    data, one row per particle. Returns (the arrays, the positions of the leaving particles
    that no rank holds). Collective."""
    sub = _take(arrays, leaving)
    x, cells, X = sub.pop("x"), sub.pop("cells"), sub.pop("X")
    d = distribute(locator, x, sub, cells=cells, X=X)  # none is found here: the result is the arrivals
    arrivals = {"x": d.x, "cells": d.cells, "X": d.X, **d.data}
    return replace_rows(arrays, leaving, arrivals), d.outside
