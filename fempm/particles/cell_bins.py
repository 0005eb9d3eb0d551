"""Cell bounding boxes hashed into a uniform grid of bins, to find the cells that may hold
given points or overlap given boxes."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from fempm.meshes.geometry import CellGeometry

__all__ = ["CellBins"]


class CellBins:
    """Bounding boxes of a set of cells, hashed into a uniform grid of bins of about one cell
    size, to find the cells whose bounding boxes overlap given boxes (vectorised)."""

    def __init__(self, geometry: CellGeometry, cells: npt.NDArray[np.int32]):
        self.cells = np.asarray(cells, dtype=np.int32)
        nodes = geometry.x[geometry.dofmap[self.cells]]  # (nc, nn, d)
        self.lo, self.hi = nodes.min(axis=1), nodes.max(axis=1)
        d = geometry.gdim
        if len(self.cells) == 0:
            self.origin, self.size, self.shape = np.zeros(d), 1.0, np.ones(d, dtype=np.int64)
            self.start, self.members = np.zeros(2, dtype=np.int64), np.zeros(0, dtype=np.int64)
            return
        self.size = float(np.median((self.hi - self.lo).max(axis=1)))
        self.origin = self.lo.min(axis=0)
        self.shape = np.maximum(np.floor((self.hi.max(axis=0) - self.origin) / self.size).astype(np.int64) + 1, 1)
        owner, bins = self._expand(self.lo, self.hi)
        order = np.argsort(bins, kind="stable")
        self.members = owner[order]  # positions into self.cells, grouped by bin
        self.start = np.searchsorted(bins[order], np.arange(np.prod(self.shape) + 1))

    def _range(self, lo: npt.NDArray, hi: npt.NDArray) -> tuple[npt.NDArray, npt.NDArray]:
        i0 = np.clip(np.floor((lo - self.origin) / self.size).astype(np.int64), 0, self.shape - 1)
        i1 = np.clip(np.floor((hi - self.origin) / self.size).astype(np.int64), 0, self.shape - 1)
        return i0, i1

    def _expand(self, lo: npt.NDArray, hi: npt.NDArray) -> tuple[npt.NDArray, npt.NDArray]:
        """All (box, bin) pairs of boxes [lo, hi] (clipped to the grid)."""
        i0, i1 = self._range(lo, hi)
        span = i1 - i0 + 1  # (m, d)
        count = np.prod(span, axis=1)
        box = np.repeat(np.arange(len(lo)), count)
        k = np.arange(len(box)) - np.repeat(np.cumsum(count) - count, count)  # index within the box's bins
        flat = np.zeros(len(box), dtype=np.int64)
        for a in range(lo.shape[1]):  # loop over axes: unravel k over the box's bin range
            s = span[box, a]
            flat = flat * self.shape[a] + i0[box, a] + k % s
            k = k // s
        return box, flat

    def candidates(self, lo: npt.NDArray, hi: npt.NDArray) -> tuple[npt.NDArray, npt.NDArray]:
        """Pairs (box index, position in :attr:`cells`) whose bounding boxes overlap, each once."""
        if len(self.cells) == 0 or len(lo) == 0:
            return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int32)
        outside = np.any((hi < self.origin) | (lo > self.origin + self.shape * self.size), axis=1)
        box, bins = self._expand(lo, hi)
        keep = ~outside[box]
        box, bins = box[keep], bins[keep]
        n = self.start[bins + 1] - self.start[bins]
        pb = np.repeat(box, n)
        pos = np.repeat(self.start[bins] - np.cumsum(n) + n, n) + np.arange(n.sum())
        pc = self.members[pos]
        hit = np.all((self.lo[pc] <= hi[pb]) & (self.hi[pc] >= lo[pb]), axis=1)
        key = np.unique(pb[hit] * len(self.cells) + pc[hit])
        return key // len(self.cells), key % len(self.cells)
