"""Output as a run goes: energies CSV (flushed every row), particle frames as VTK PolyData
(legacy binary, one file per frame, gathered on rank 0), grid velocity and stress with VTXWriter, and a
JSON summary."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import dolfinx.fem
import dolfinx.io
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.particles import Particles


def write_vtk_points(path: Path, x: npt.NDArray, data: dict[str, npt.NDArray]) -> None:
    """Legacy binary VTK PolyData: points (n, 3) with point data (scalars, vectors, tensors)."""
    n = len(x)
    with open(path, "wb") as f:
        f.write(b"# vtk DataFile Version 3.0\nfempm particles\nBINARY\nDATASET POLYDATA\n")
        f.write(f"POINTS {n} double\n".encode())
        f.write(np.ascontiguousarray(x, dtype=">f8").tobytes())
        f.write(f"\nVERTICES {n} {2 * n}\n".encode())
        f.write(np.column_stack([np.ones(n), np.arange(n)]).astype(">i4").tobytes())
        f.write(f"\nPOINT_DATA {n}\n".encode())
        for name, a in data.items():
            a = np.asarray(a, dtype=">f8").reshape(n, -1)
            kind = {1: "SCALARS {} double 1\nLOOKUP_TABLE default", 3: "VECTORS {} double", 9: "TENSORS {} double"}[a.shape[1]]
            f.write((kind.format(name) + "\n").encode())
            f.write(a.tobytes())
            f.write(b"\n")


def _pad3(a: npt.NDArray) -> npt.NDArray:
    """Vectors (n, d) -> (n, 3); tensors (n, d, d) -> (n, 3, 3)."""
    if a.ndim == 2:
        return np.pad(a, ((0, 0), (0, 3 - a.shape[1])))
    return np.pad(a, ((0, 0), (0, 3 - a.shape[1]), (0, 3 - a.shape[2])))


class OutputFolderError(OSError):
    """The output folder cannot be created or written (raised on every rank alike)."""


def make_folder(folder: Path, comm) -> None:
    """Create ``folder`` (and ``folder/particles``) on rank 0; an :class:`OutputFolderError`
    on every rank if that fails (collective: no rank is left waiting)."""
    error = None
    if comm.rank == 0:
        try:
            (folder / "particles").mkdir(parents=True, exist_ok=True)
            probe = folder / ".fempm-write-test"
            probe.touch()
            probe.unlink()
        except OSError as e:
            error = f"cannot write the output folder {str(folder)!r}: {e.strerror or e}"
    error = comm.bcast(error, root=0)
    if error is not None:
        raise OutputFolderError(error)


class RunWriter:
    """Writes a run's outputs into ``folder`` as the run goes (nothing kept only in memory)."""

    def __init__(self, folder: Path, particles: Particles, V: dolfinx.fem.FunctionSpace | None = None,
                 *, png: bool = False):
        self.folder = Path(folder)
        self.png = png
        x = particles.mesh.geometry.x
        lo, hi = x.min(axis=0, initial=np.inf), x.max(axis=0, initial=-np.inf)
        particles.comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
        particles.comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
        self.bounds = np.array([lo, hi])
        self.comm = particles.comm
        self.frame = 0
        self._csv = None
        self._stress_vtx = None
        make_folder(self.folder, self.comm)
        self.grid_v = dolfinx.fem.Function(V, name="grid_velocity") if V is not None else None
        self._vtx = (
            dolfinx.io.VTXWriter(self.comm, self.folder / "grid_velocity.bp", [self.grid_v], engine="BP4")
            if V is not None
            else None
        )

    def energies(self, row: dict) -> None:
        if self.comm.rank != 0:
            return
        if self._csv is None:
            self._file = open(self.folder / "energies.csv", "w", newline="")
            self._csv = csv.DictWriter(self._file, fieldnames=list(row))
            self._csv.writeheader()
        self._csv.writerow(row)
        self._file.flush()

    def particles(self, particles: Particles, t: float) -> None:
        f = particles.fields
        local = {
            "x": _pad3(particles.x),
            "velocity": _pad3(f["v"]),
            "stress": _pad3(f["sigma"]).reshape(len(particles), 9),
            "J": np.linalg.det(f["F"]),
            "id": particles.ids.astype(float),
            "body": f["body"].astype(float),
        }
        parts = self.comm.gather(local, root=0)
        if self.comm.rank == 0:
            allp = {k: np.concatenate([p[k] for p in parts]) for k in local}
            x = allp.pop("x")
            write_vtk_points(self.folder / "particles" / f"particles_{self.frame:05d}.vtk", x, allp)
            with open(self.folder / "particles" / "times.csv", "a") as fh:
                fh.write(f"{self.frame},{float(t)!r}\n")  # a plain number, not np.float64(...)
            if self.png:
                from fempm.plot import plot_particle_frame

                speed = np.linalg.norm(allp["velocity"], axis=1)
                plot_particle_frame(x, speed, self.folder / "frames" / f"frame_{self.frame:05d}.png",
                                    title=f"t = {t:.4g}", label="|velocity|", bounds=self.bounds)
        self.frame += 1

    def grid(self, v: npt.NDArray, t: float, stress: dolfinx.fem.Function | None = None) -> None:
        """Grid velocity (``grid_velocity.bp``) and, when given, grid stress (``grid_stress.bp``)
        at time ``t`` (VTX, open in ParaView). Collective."""
        if self._vtx is None:
            return
        self.grid_v.x.array[:] = v.ravel()
        self._vtx.write(t)
        if stress is not None:
            if self._stress_vtx is None:
                self.grid_sigma = dolfinx.fem.Function(stress.function_space, name="grid_stress")
                self._stress_vtx = dolfinx.io.VTXWriter(self.comm, self.folder / "grid_stress.bp", [self.grid_sigma],
                                                        engine="BP4")
            self.grid_sigma.x.array[:] = stress.x.array
            self._stress_vtx.write(t)

    def summary(self, data: dict) -> None:
        if self.comm.rank == 0:
            (self.folder / "summary.json").write_text(json.dumps(data, indent=2, default=float))

    def close(self) -> None:
        for vtx in (self._vtx, self._stress_vtx):
            if vtx is not None:
                vtx.close()
        if self.comm.rank == 0 and self._csv is not None:
            self._file.close()
