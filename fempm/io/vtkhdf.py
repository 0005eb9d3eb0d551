"""Particle frames as VTKHDF: one file per frame for all ranks, the arrays raw. pyvista reads a
frame (``pyvista.read``: an UnstructuredGrid) and the run's series (``pyvista.PVDReader`` on
``particles.pvd``, which names these files; VTK 9.7, tested); ParaView opens the files with its
VTKHDF reader (5.12 and later), a numbered series as one, and the ``.pvd`` where its VTK's
collection reader takes VTKHDF files (``--frame-format vtu`` writes VTK XML, which every
version reads).

The file is one UnstructuredGrid piece: the particles of every rank, rank after rank, each a
vertex cell, with their point data. Rank 0 lays the file out with h5py (every dataset
contiguous, its space allocated at creation and never filled) and tells the ranks where each
dataset starts; every rank then writes its own rows at their byte offsets at the same time
(``os.pwrite``: parallel writes into one file without MPI-IO, which the wheel's HDF5 lacks), and
rank 0 renames the finished file into place, so that a run killed while it writes leaves the
frames before, never half a frame.

Why not the VTK XML pieces (:mod:`fempm.io.vtu`, still written with ``frame_format="vtu"``):
their base64 encoding costs several times the raw write and a file per rank
(docs/performance.md); why not ADIOS2: the wheel's ADIOS2 is DOLFINx's, without Python bindings
for arbitrary arrays, and the ``adios2`` package would add a second MPI-built library for what
h5py's layout and a positional write do here.
"""

from __future__ import annotations

import os
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
    """h5py, checked to run on the HDF5 it was built for: in one process with DOLFINx, whose
    wheel loads its own HDF5 (1.14) first, an h5py built for another (h5py 3.16 bundles HDF5
    2.0) fails on its first dataset with "Not a datatype"."""
    try:
        import h5py
    except ImportError as e:  # pragma: no cover - depends on the installation
        raise ImportError("VTKHDF frames need h5py: pip install 'h5py<3.16' (or frame_format='vtu')") from e
    running, built = h5py.version.hdf5_version_tuple[:2], h5py.version.hdf5_built_version_tuple[:2]
    if running != built:  # pragma: no cover - depends on the installation
        raise ImportError(f"h5py {h5py.__version__} was built for HDF5 {'.'.join(map(str, built))} but runs on "
                          f"{'.'.join(map(str, running))} (DOLFINx's): install an h5py built for DOLFINx's HDF5 "
                          "(pip install 'h5py<3.16'), or write frames with frame_format='vtu'")
    return h5py


def _index_type(total: int) -> type:
    """The integer type of the cells' connectivity and offsets (VTK reads either)."""
    return np.int32 if total < 2**31 - 1 else np.int64


def _stored(a: npt.NDArray, vector: bool) -> tuple[int, ...]:
    """The shape of a row as written: a (d, d) tensor as 9 components, a vector as 3."""
    if a.ndim == 3:
        return (9,)
    return (3,) if vector else a.shape[1:]


def _create(path: Path, total: int, specs: dict[str, tuple[np.dtype, tuple[int, ...]]]) -> dict[str, int]:
    """The file with every dataset laid out at its full size, unwritten (rank 0); returns each
    dataset's byte offset in the file (``Types``, ``Connectivity``, ``Offsets``, ``Points`` and
    ``PointData/NAME`` for the ``specs`` (dtype, row shape))."""
    h5py = _h5py()
    dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
    dcpl.set_alloc_time(h5py.h5d.ALLOC_TIME_EARLY)  # the space is there now, contiguous
    dcpl.set_fill_time(h5py.h5d.FILL_TIME_NEVER)  # and not written twice
    index = _index_type(total)
    layout = {"Types": (np.dtype(np.uint8), (), total), "Connectivity": (np.dtype(index), (), total),
              "Offsets": (np.dtype(index), (), total + 1), "Points": (np.dtype(np.float64), (3,), total)}
    layout.update({f"PointData/{k}": (np.dtype(t), shape, total) for k, (t, shape) in specs.items()})
    with h5py.File(path, "w") as f:
        root = f.create_group("VTKHDF")
        root.attrs["Version"] = np.array(VERSION, dtype=np.int64)
        root.attrs.create("Type", np.bytes_(_TYPE), dtype=h5py.string_dtype("ascii", len(_TYPE)))
        for name in ("NumberOfPoints", "NumberOfCells", "NumberOfConnectivityIds"):
            root.create_dataset(name, data=np.array([total], dtype=np.int64))
        root.create_group("PointData")
        made = {name: root.create_dataset(name, (rows, *shape), dtype=dtype, dcpl=dcpl)
                for name, (dtype, shape, rows) in layout.items()}
        return {name: ds.id.get_offset() for name, ds in made.items()}


def _pwrite(fd: int, a: npt.NDArray, offset: int) -> None:
    view = memoryview(np.ascontiguousarray(a)).cast("B")
    while len(view):
        done = os.pwrite(fd, view, offset)
        view, offset = view[done:], offset + done


def _write(fd: int, offset: int | None, start: int, a: npt.NDArray, vector: bool) -> None:
    """Rows ``a`` of a dataset at byte ``offset`` from row ``start``; padded ones (vectors to 3
    components, tensors to 3 x 3) through a small buffer, :data:`BLOCK` rows at a time (no copy
    of the whole array, no fresh pages to fault in)."""
    if offset is None or not len(a):  # (an empty dataset has no place in the file)
        return
    shape = _stored(a, vector)
    row = a.dtype.itemsize * int(np.prod(shape))
    if shape == a.shape[1:]:
        _pwrite(fd, a, offset + start * row)
        return
    buf = np.zeros((min(BLOCK, len(a)), *shape), dtype=a.dtype)
    d = a.shape[1]
    for lo in range(0, len(a), BLOCK):
        m = min(BLOCK, len(a) - lo)
        if a.ndim == 3:
            buf[:m].reshape(m, 3, 3)[:, :d, :d] = a[lo:lo + m]
        else:
            buf[:m, :d] = a[lo:lo + m]
        _pwrite(fd, buf[:m], offset + (start + lo) * row)


def _fill(path: Path, offsets: dict[str, int], start: int, total: int, x: npt.NDArray, data: dict[str, npt.NDArray],
          vectors, last: bool) -> None:
    """This rank's rows from ``start`` (of ``total``), at the datasets' ``offsets``; the
    ``last`` rank also the closing entry of ``Offsets``."""
    n = len(x)
    index = _index_type(total)
    fd = os.open(path, os.O_WRONLY)
    try:
        _write(fd, offsets["Types"], start, np.full(n, _VERTEX, dtype=np.uint8), False)
        ids = np.arange(start, start + n + (1 if last else 0), dtype=index)
        _write(fd, offsets["Connectivity"], start, ids[:n], False)
        _write(fd, offsets["Offsets"], start, ids, False)
        _write(fd, offsets["Points"], start, x, True)
        for name, a in data.items():
            _write(fd, offsets[f"PointData/{name}"], start, a, name in vectors)
    finally:
        os.close(fd)


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
        Collective. Every rank writes its own rows at once; nothing is gathered.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    counts = comm.allgather(len(x))
    start, total = sum(counts[: comm.rank]), sum(counts)
    error: BaseException | None = None
    offsets = None
    if comm.rank == 0:
        try:
            offsets = _create(tmp, total, {k: (a.dtype, _stored(a, k in vectors)) for k, a in data.items()})
        except Exception as e:  # noqa: BLE001 - agreed on below
            error = e
    offsets = comm.bcast(offsets, root=0)
    if offsets is not None:
        try:
            _fill(tmp, offsets, start, total, x, data, vectors, comm.rank == comm.size - 1)
        except Exception as e:  # noqa: BLE001
            error = e
    if comm.allreduce(error is not None, op=MPI.LOR):
        if comm.rank == 0:
            tmp.unlink(missing_ok=True)
    elif comm.rank == 0:
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
