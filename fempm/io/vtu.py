"""Frames as VTK XML, written in parallel: each rank writes its own piece (``.vtu``, an
UnstructuredGrid with the point data inline, base64 binary: the particles as vertex cells, a
grid field on the rank's cells), rank 0 the index of the pieces (``.pvtu``) and the time
collection (``.pvd``). Nothing is gathered; ParaView and pyvista (``pyvista.read``,
``pyvista.PVDReader``) read all three on a fresh install (the VTK XML readers are in every VTK
build)."""

from __future__ import annotations

import base64
import os
import sys
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
import numpy.typing as npt

__all__ = ["write_atomic", "write_collection", "write_index", "write_piece"]

_TYPES = {np.dtype(np.float64): "Float64", np.dtype(np.int64): "Int64", np.dtype(np.int32): "Int32",
          np.dtype(np.uint8): "UInt8"}
_ORDER = "LittleEndian" if sys.byteorder == "little" else "BigEndian"
_HEADER = f'<?xml version="1.0"?>\n<VTKFile type="{{}}" version="1.0" byte_order="{_ORDER}" header_type="UInt64">\n'


def _array(a: npt.NDArray, name: str | None = None) -> str:
    """A DataArray element, base64 "binary" (an UInt64 byte count, then the values)."""
    a = np.ascontiguousarray(a)
    comps = 1 if a.ndim == 1 else a.shape[1]
    raw = a.tobytes()
    data = base64.b64encode(np.uint64(len(raw)).tobytes() + raw).decode()
    label = f" Name={quoteattr(name)}" if name is not None else ""
    return (f'<DataArray type="{_TYPES[a.dtype]}"{label} NumberOfComponents="{comps}" format="binary">'
            f"{data}</DataArray>\n")


def _declare(a: npt.NDArray, name: str | None = None) -> str:
    comps = 1 if a.ndim == 1 else a.shape[1]
    label = f" Name={quoteattr(name)}" if name is not None else ""
    return f'<PDataArray type="{_TYPES[np.asarray(a).dtype]}"{label} NumberOfComponents="{comps}"/>\n'


def write_piece(path: Path, x: npt.NDArray, data: dict[str, npt.NDArray],
                cells: tuple[npt.NDArray, npt.NDArray] | None = None) -> None:
    """One rank's points ``x`` (n, 3) with point ``data`` (n,) or (n, k) as a ``.vtu``; without
    ``cells`` a vertex per point (a point cloud), else ``cells = (connectivity (c, k), VTK
    types (c,))``: c cells of k points each, in VTK's node order (:func:`dolfinx.plot.vtk_mesh`)."""
    n = len(x)
    if cells is None:
        conn, offsets, types = np.arange(n, dtype=np.int64), np.arange(1, n + 1, dtype=np.int64), np.ones(n, np.uint8)
    else:
        topology, kinds = cells
        conn = np.asarray(topology, dtype=np.int64).ravel()
        offsets = np.arange(1, len(topology) + 1, dtype=np.int64) * np.shape(topology)[1]
        types = np.asarray(kinds, dtype=np.uint8)
    out = [_HEADER.format("UnstructuredGrid"), "<UnstructuredGrid>\n",
           f'<Piece NumberOfPoints="{n}" NumberOfCells="{len(types)}">\n<PointData>\n']
    out += [_array(a, name) for name, a in data.items()]
    out += ["</PointData>\n<Points>\n", _array(np.asarray(x, dtype=np.float64)), "</Points>\n<Cells>\n",
            _array(conn, "connectivity"), _array(offsets, "offsets"), _array(types, "types"),
            "</Cells>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n"]
    Path(path).write_text("".join(out))


def write_index(path: Path, pieces: list[str], x: npt.NDArray, data: dict[str, npt.NDArray]) -> None:
    """The ``.pvtu`` naming the ``pieces`` (file names next to it); ``x`` and ``data`` give the
    arrays' types and components (any rows)."""
    out = [_HEADER.format("PUnstructuredGrid"), '<PUnstructuredGrid GhostLevel="0">\n<PPointData>\n']
    out += [_declare(a, name) for name, a in data.items()]
    out += ["</PPointData>\n<PPoints>\n", _declare(np.asarray(x, dtype=np.float64)), "</PPoints>\n"]
    out += [f"<Piece Source={quoteattr(p)}/>\n" for p in pieces]
    out += ["</PUnstructuredGrid>\n</VTKFile>\n"]
    write_atomic(path, "".join(out))


def write_collection(path: Path, frames: list[tuple[float, str]]) -> None:
    """The ``.pvd`` time collection of (time, file relative to ``path``'s folder) frames,
    written atomically (:func:`write_atomic`): a run killed while it rewrites the collection
    leaves the one before."""
    out = [_HEADER.format("Collection"), "<Collection>\n"]
    out += [f'<DataSet timestep="{float(t)!r}" part="0" file={quoteattr(f)}/>\n' for t, f in frames]
    out += ["</Collection>\n</VTKFile>\n"]
    write_atomic(path, "".join(out))


def write_atomic(path: Path, text: str) -> None:
    """``text`` into ``path`` through a temporary file beside it and ``os.replace``: the file
    holds the new text or the old one, never part of either. Local: any rank may call it."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
