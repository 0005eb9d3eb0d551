"""Frame series as a run writes them: per frame, the files of all ranks (VTK XML pieces and
their index, :class:`FrameSeries`; or one VTKHDF file, :class:`PointFileSeries`), the frames'
times (CSV) and the ``.pvd`` collection naming them, rewritten with every frame; a continued
run drops the frames after its checkpoint (:meth:`FrameSeries.truncate`)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.io import vtkhdf, vtu

__all__ = ["FRAME_FORMATS", "FrameSeries", "OutputWriteError", "PointFileSeries", "everywhere", "read_times",
           "vtk_layout"]


def vtk_layout(a: npt.NDArray, vector: bool = True) -> npt.NDArray:
    """VTK's layout of an array of rows: vectors (n, d) -> (n, 3), tensors (n, d, d) -> (n, 9)
    (zeros in the added places); others as they are."""
    if a.ndim == 3:
        out = np.zeros((len(a), 3, 3), dtype=a.dtype)
        out[:, :a.shape[1], :a.shape[2]] = a
        return out.reshape(len(a), 9)
    if vector:
        out = np.zeros((len(a), 3), dtype=a.dtype)
        out[:, :a.shape[1]] = a
        return out
    return a


class OutputWriteError(OSError):
    """Writing an output failed on some rank during a run (raised on every rank alike; the
    message names the failing ranks and their errors)."""


def everywhere(comm: MPI.Comm, what: str, action: Callable[[], None], *, root_only: bool = False) -> None:
    """``action`` on every rank (or rank 0 with ``root_only``), then an
    :class:`OutputWriteError` on every rank if it failed on any. Collective."""
    error = None
    if not root_only or comm.rank == 0:
        try:
            action()
        except OSError as e:
            error = f"rank {comm.rank}: {e}"
    errors = [e for e in comm.allgather(error) if e] if comm.size > 1 else [error] if error else []
    if errors:
        raise OutputWriteError(f"writing {what} failed ({'; '.join(errors)})")


def read_times(path: Path) -> list[tuple[int, float]]:
    """The (frame, time) rows of a times file; a last line a kill cut short (no newline yet) is
    not one."""
    if not path.exists():
        return []
    text = path.read_text()
    complete = text[: text.rfind("\n") + 1]
    return [(int(k), float(t)) for k, t in (line.split(",") for line in complete.splitlines() if line)]


class FrameSeries:
    """A time series of one output in VTK XML: each rank's piece ``DIR/STEM_NNNNN_rRRRRR.vtu``
    (``NNNNN`` the run's frame number), their index ``DIR/STEM_NNNNN.pvtu``, the collection
    ``OUT/STEM.pvd`` and the frames' times ``times`` (CSV rows ``frame,t``; default
    ``DIR/STEM_times.csv``). The collection is rewritten with every frame. The folder is made
    at the first frame."""

    #: the file of a frame that the collection names, and the files of a frame (glob patterns)
    suffix, patterns = ".pvtu", ("{stem}_*.*vtu",)

    def __init__(self, out: Path, folder: str, stem: str, comm: MPI.Comm, times: Path | None = None):
        self.out, self.folder, self.stem, self.comm = Path(out), Path(out) / folder, stem, comm
        self.times_path = times or self.folder / f"{stem}_times.csv"
        self.frames = read_times(self.times_path) if comm.rank == 0 else []  # (frame, time) written (rank 0)
        self._made = False

    def _name(self, frame: int) -> str:
        return f"{self.stem}_{frame:05d}"

    def write(self, frame: int, t: float, x: npt.NDArray, data: dict[str, npt.NDArray],
              cells: tuple[npt.NDArray, npt.NDArray] | None = None, vectors: tuple[str, ...] = ()) -> None:
        """Frame ``frame`` at time ``t``: this rank's points ``x`` (n, 3), point ``data`` and
        ``cells`` (:func:`fempm.io.vtu.write_piece`); ``vectors``: the names of ``data``'s
        vectors, for a series that pads them as it writes (:class:`PointFileSeries`). Ranks
        without points write no piece (one piece at least, rank 0's). Collective."""
        name = self._name(frame)
        if not self._made:  # the allgather after rank 0's mkdir: no rank writes into it before
            everywhere(self.comm, f"the folder {self.folder}", lambda: self.folder.mkdir(parents=True, exist_ok=True),
                        root_only=True)
            self._made = True
        index = self._write_frame(name, frame, x, data, cells, vectors)

        def collection():
            index()
            with open(self.times_path, "a", newline="") as fh:
                fh.write(f"{frame},{float(t)!r}\n")  # a plain number, not np.float64(...)
            self.frames.append((frame, float(t)))
            self._collection()

        everywhere(self.comm, f"the index of {self.stem} frame {frame}", collection, root_only=True)

    def write_points(self, frame: int, t: float, x: npt.NDArray, data: dict[str, npt.NDArray],
                     vectors: tuple[str, ...] = ()) -> None:
        """A point cloud as frame ``frame``: ``x`` (n, d) and ``data`` as
        :func:`fempm.io.vtkhdf.write_points` takes them (vectors and (d, d) tensors padded to VTK's
        3 and 3 x 3 here). Collective."""
        data = {k: vtk_layout(a, k in vectors) for k, a in data.items()}
        self.write(frame, t, vtk_layout(x, True), data)

    def _write_frame(self, name: str, frame: int, x: npt.NDArray, data: dict[str, npt.NDArray],
                     cells, vectors: tuple[str, ...]) -> Callable[[], None]:
        """Write the frame's files (collective); returns what rank 0 writes after them."""
        ranks = [r for r, c in enumerate(self.comm.allgather(len(x))) if c] or [0]  # ranks holding points

        def piece():
            if self.comm.rank in ranks:
                vtu.write_piece(self.folder / f"{name}_r{self.comm.rank:05d}.vtu", x, data, cells)

        everywhere(self.comm, f"{self.stem} frame {frame}", piece)
        return lambda: vtu.write_index(self.folder / f"{name}.pvtu", [f"{name}_r{r:05d}.vtu" for r in ranks], x, data)

    def _collection(self) -> None:
        vtu.write_collection(self.out / f"{self.stem}.pvd",
                             [(t, f"{self.folder.name}/{self._name(k)}{self.suffix}") for k, t in self.frames])

    def truncate(self, frames: int) -> None:
        """Drop the frames numbered ``frames`` and later (a continued run's outputs after its
        checkpoint) and rewrite the times and the collection; rank 0 only."""
        self.frames = [(k, t) for k, t in read_times(self.times_path) if k < frames]
        if self.times_path.exists():
            vtu.write_atomic(self.times_path, "".join(f"{k},{t!r}\n" for k, t in self.frames))
        for pattern in self.patterns:
            for q in self.folder.glob(pattern.format(stem=self.stem)):
                number = q.stem[len(self.stem) + 1:].split("_")[0]
                if number.isdigit() and int(number) >= frames:
                    q.unlink()
        if self.frames or (self.out / f"{self.stem}.pvd").exists():
            self._collection()


class PointFileSeries(FrameSeries):
    """A time series of point clouds in VTKHDF: one file ``DIR/STEM_NNNNN.vtkhdf`` per frame for
    all ranks (:mod:`fempm.io.vtkhdf`), the collection ``OUT/STEM.pvd`` naming them, the times
    as :class:`FrameSeries`'s. Points only (no cells)."""

    suffix, patterns = ".vtkhdf", ("{stem}_*.vtkhdf",)

    def write_points(self, frame: int, t: float, x: npt.NDArray, data: dict[str, npt.NDArray],
                     vectors: tuple[str, ...] = ()) -> None:
        self.write(frame, t, x, data, vectors=vectors)  # padded as they are written, a block at a time

    def _write_frame(self, name: str, frame: int, x: npt.NDArray, data: dict[str, npt.NDArray],
                     cells, vectors: tuple[str, ...]) -> Callable[[], None]:
        if cells is not None:
            raise ValueError("VTKHDF frames hold point clouds: write cells as VTK XML (FrameSeries)")
        everywhere(self.comm, f"{self.stem} frame {frame}",
                   lambda: vtkhdf.write_points(self.folder / f"{name}{self.suffix}", self.comm, x, data, vectors))
        return lambda: None


#: the particle frames' formats (:class:`RunWriter`'s ``frame_format``): VTKHDF, one file per
#: frame for all ranks, or VTK XML, a piece per rank and their index
FRAME_FORMATS = {"vtkhdf": PointFileSeries, "vtu": FrameSeries}
