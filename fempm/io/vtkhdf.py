"""Particle frames as VTKHDF: one file per frame for all ranks, the arrays raw (HDF5 through
h5py), read by ParaView (5.12 and later) and pyvista (``pyvista.read``, and
``pyvista.PVDReader`` on the run's ``particles.pvd``, which names these files).

The file is one UnstructuredGrid piece: the particles of every rank, rank after rank, each a
vertex cell, with their point data. Rank 0 makes the file with every dataset at its full size;
the ranks then write their rows in turn (an HDF5 file without MPI-IO takes one writer at a
time: the ranks pass a token), and rank 0 renames the finished file into place, so that a run
killed while it writes leaves the frames before, never half a frame.

Why not the VTK XML pieces (:mod:`fempm.io.vtu`, still written with ``frame_format="vtu"``):
at 1e6 particles their base64 encoding costs several times the raw write (docs/performance.md);
why not ADIOS2: the wheel's ADIOS2 is DOLFINx's, without Python bindings for arbitrary arrays,
and the ``adios2`` package would add a second MPI-built library for what h5py does here.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

__all__ = ["BLOCK", "VERSION", "read_points", "write_points"]

#: the VTKHDF format version written
VERSION = (2, 2)
_TYPE = "UnstructuredGrid"
_VERTEX = 1  # VTK_VERTEX
#: rows padded at a time
BLOCK = 1 << 15


def _h5py():
    try:
        import h5py
    except ImportError as e:  # pragma: no cover - depends on the installation
        raise ImportError("VTKHDF frames need h5py: pip install h5py (or frame_format='vtu')") from e
    return h5py


def _create(path: Path, total: int, dtypes: dict[str, tuple[np.dtype, tuple[int, ...]]]) -> None:
    """The file with every dataset at its full size (rank 0)."""
    h5py = _h5py()
    with h5py.File(path, "w") as f:
        root = f.create_group("VTKHDF")
        root.attrs["Version"] = np.array(VERSION, dtype=np.int64)
        root.attrs.create("Type", np.bytes_(_TYPE), dtype=h5py.string_dtype("ascii", len(_TYPE)))
        for name in ("NumberOfPoints", "NumberOfCells", "NumberOfConnectivityIds"):
            root.create_dataset(name, data=np.array([total], dtype=np.int64))
        root.create_dataset("Points", (total, 3), dtype=np.float64)
        root.create_dataset("Types", data=np.full(total, _VERTEX, dtype=np.uint8))
        index = np.int32 if total < 2**31 - 1 else np.int64  # (VTK reads either)
        root.create_dataset("Connectivity", data=np.arange(total, dtype=index))
        root.create_dataset("Offsets", data=np.arange(total + 1, dtype=index))
        data = root.create_group("PointData")
        for name, (dtype, shape) in dtypes.items():
            data.create_dataset(name, (total, *shape), dtype=dtype)


def _stored(a: npt.NDArray, vector: bool) -> tuple[int, ...]:
    """The shape of a row as written: a (d, d) tensor as 9 components, a vector as 3."""
    if a.ndim == 3:
        return (9,)
    return (3,) if vector else a.shape[1:]


def _write(dataset, start: int, a: npt.NDArray, vector: bool) -> None:
    """Rows ``a`` into ``dataset`` from ``start``; padded ones (vectors to 3 components,
    tensors to 3 x 3) through a small buffer, :data:`BLOCK` rows at a time (no copy of the
    whole array, no fresh pages to fault in)."""
    shape = _stored(a, vector)
    if shape == a.shape[1:]:
        dataset[start:start + len(a)] = a
        return
    buf = np.zeros((min(BLOCK, len(a)), *shape), dtype=a.dtype)
    d = a.shape[1]
    for lo in range(0, len(a), BLOCK):
        m = min(BLOCK, len(a) - lo)
        if a.ndim == 3:
            buf[:m].reshape(m, 3, 3)[:, :d, :d] = a[lo:lo + m]
        else:
            buf[:m, :d] = a[lo:lo + m]
        dataset[start + lo:start + lo + m] = buf[:m]


def _fill(path: Path, start: int, x: npt.NDArray, data: dict[str, npt.NDArray], vectors) -> None:
    """This rank's rows from ``start``."""
    with _h5py().File(path, "r+") as f:
        root = f["VTKHDF"]
        _write(root["Points"], start, x, True)
        for name, a in data.items():
            _write(root["PointData"][name], start, a, name in vectors)


def _idle(request):
    """Wait for ``request`` without spinning: MPI's blocking calls poll a core while the rank
    writing takes the other (on this machine's two cores the writer ran at half speed)."""
    while True:
        done, value = request.test()
        if done:
            return value
        time.sleep(2e-4)


def write_points(path: str | Path, comm: MPI.Comm, x: npt.NDArray, data: dict[str, npt.NDArray],
                 vectors: tuple[str, ...] = ()) -> None:
    """Every rank's points ``x`` (n, d) and point ``data`` ((n,), (n, k) or (n, d, d) arrays,
    the same names, shapes and types on every rank) into one VTKHDF file ``path``.

    VTK's layout: the points with 3 coordinates, the arrays named in ``vectors`` with 3
    components, a (d, d) tensor as 9 components (row by row, 3 x 3), each padded with zeros;
    other arrays as they are.

    Args:
        path: The file (the same on every rank); written as ``.NAME.tmp`` beside it, then
            renamed.
        comm: The ranks that hold points.
        x: This rank's points (n, d), d <= 3.
        data: This rank's point data.
        vectors: The names of ``data``'s vectors (n, d).

    Raises:
        OSError: This rank could not write, whatever the cause (the other ranks go on: the
            caller agrees on the failure, :class:`fempm.io.writers.RunWriter`).

    Note:
        Collective. The ranks write one after the other; nothing is gathered.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    counts = comm.allgather(len(x))
    start, total = sum(counts[: comm.rank]), sum(counts)
    error: BaseException | None = None
    if comm.rank == 0:
        try:
            _create(tmp, total, {k: (a.dtype, _stored(a, k in vectors)) for k, a in data.items()})
        except Exception as e:  # noqa: BLE001 - passed on with the token, raised below
            error = e
    ok = comm.bcast(error is None, root=0)
    if comm.rank > 0:  # the token: the rank before has written (or failed)
        ok = _idle(comm.irecv(source=comm.rank - 1, tag=77)) and ok
    if ok and counts[comm.rank]:
        try:
            _fill(tmp, start, x, data, vectors)
        except Exception as e:  # noqa: BLE001
            error, ok = e, False
    if comm.rank + 1 < comm.size:
        comm.send(ok, dest=comm.rank + 1, tag=77)
    last = np.array([ok], dtype=np.int8)
    _idle(comm.Ibcast(last, root=comm.size - 1))
    ok = bool(last[0])
    if comm.rank == 0 and ok:
        try:
            os.replace(tmp, path)
        except OSError as e:
            error = e
    if isinstance(error, OSError):
        raise error
    if error is not None:
        raise OSError(f"{path}: {type(error).__name__}: {error}") from error


def read_points(path: str | Path) -> tuple[npt.NDArray, dict[str, npt.NDArray]]:
    """The points (n, 3) and point data of a file :func:`write_points` wrote (local)."""
    with _h5py().File(path, "r") as f:
        root = f["VTKHDF"]
        return root["Points"][()], {k: v[()] for k, v in root["PointData"].items()}
