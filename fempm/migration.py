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
