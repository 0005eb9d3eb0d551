"""Output as a run goes: energies CSV (flushed every row), particle frames as VTK XML point
clouds written by every rank in parallel (:mod:`fempm.vtu`), grid velocity and stress with
VTK XML as well (:class:`GridSeries`), and a JSON summary."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import dolfinx.fem
import dolfinx.io
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm import vtu
from fempm.particles import Particles


def _pad3(a: npt.NDArray) -> npt.NDArray:
    """Vectors (n, d) -> (n, 3); tensors (n, d, d) -> (n, 3, 3)."""
    if a.ndim == 2:
        return np.pad(a, ((0, 0), (0, 3 - a.shape[1])))
    return np.pad(a, ((0, 0), (0, 3 - a.shape[1]), (0, 3 - a.shape[2])))


class OutputFolderError(OSError):
    """The output folder cannot be created or written (raised on every rank alike)."""


#: what a run writes into its output folder (glob patterns)
OUTPUT_FILES = ("summary.json", "energies.csv", "particles", "particles.pvd", "frames", "grid_velocity*", "grid_stress*",
           "checkpoint", "checkpoint.old", "checkpoint.tmp")


def earlier_outputs(folder: Path) -> list[Path]:
    """The outputs of an earlier run in ``folder`` (:data:`OUTPUT_FILES`)."""
    return sorted(q for pattern in OUTPUT_FILES for q in Path(folder).glob(pattern)) if Path(folder).is_dir() else []


def make_folder(folder: Path, comm, *, keep: bool = True, overwrite: bool = False) -> None:
    """Create ``folder`` (and ``folder/particles``) on rank 0; an :class:`OutputFolderError`
    on every rank if that fails (collective: no rank is left waiting). Unless ``keep`` (a
    continued run), the outputs of an earlier run there are an error, or removed with
    ``overwrite`` (only those: :data:`OUTPUT_FILES`)."""
    error = None
    earlier = [] if keep or comm.rank != 0 else earlier_outputs(folder)
    if earlier and not overwrite:
        error = (f"the output folder {str(folder)!r} holds the outputs of an earlier run "
                 f"({', '.join(q.name for q in earlier[:4])}); give --overwrite (overwrite=True) to replace them, or "
                 f"continue it: python -m fempm resume {folder}")
    elif comm.rank == 0:
        try:
            for q in earlier:
                shutil.rmtree(q) if q.is_dir() else q.unlink()
            (folder / "particles").mkdir(parents=True, exist_ok=True)
            probe = folder / ".fempm-write-test"
            probe.touch()
            probe.unlink()
        except OSError as e:
            error = f"cannot write the output folder {str(folder)!r}: {e.strerror or e}"
    error = comm.bcast(error, root=0)
    if error is not None:
        raise OutputFolderError(error)


class GridSeries:
    """A time series of one grid field in VTK XML (:class:`dolfinx.io.VTKFile`: a ``.pvd`` with
    a ``.pvtu`` and a ``.vtu`` per rank and frame, read by ParaView and pyvista on a fresh
    install). Fields of a Lagrange variant VTK cannot show point by point (Bernstein) are
    interpolated into the standard Lagrange space of the same degree, which holds them exactly."""

    def __init__(self, V: dolfinx.fem.FunctionSpace, path: Path):
        el = V.element.basix_element
        name = Path(path).stem.split("_part")[0]
        shape = V.value_shape
        self._source = None
        if V.element.interpolation_ident:
            self.u = dolfinx.fem.Function(V, name=name)
        else:
            out = dolfinx.fem.functionspace(V.mesh, ("Lagrange", el.degree, tuple(shape)))
            self.u = dolfinx.fem.Function(out, name=name)
            self._source = dolfinx.fem.Function(V)
        self.file = dolfinx.io.VTKFile(V.mesh.comm, str(path), "w")

    def write(self, values: npt.NDArray, t: float) -> None:
        """Write the field with local dof ``values`` (owned and ghost) at time ``t``; collective."""
        if self._source is None:
            self.u.x.array[:] = values
        else:
            self._source.x.array[:] = values
            self.u.interpolate(self._source)
        self.file.write_function(self.u, float(t))

    def close(self) -> None:
        self.file.close()


class RunWriter:
    """Writes a run's outputs into ``folder`` as the run goes (nothing kept only in memory)."""

    def __init__(self, folder: Path, particles: Particles, V: dolfinx.fem.FunctionSpace | None = None,
                 *, png: bool = False, resume: dict | None = None, overwrite: bool = True):
        """``resume``: the :meth:`state` of the writer of the run being continued (from its
        checkpoint): the energies and frames written after it are dropped, the frames go on
        from its count, and the grid frames go into ``grid_velocity_partK.pvd`` (and
        ``grid_stress_partK.pvd``) for the K-th continuation.
        Otherwise the outputs of an earlier run in ``folder`` are removed with ``overwrite``,
        else refused (:func:`make_folder`)."""
        self.folder = Path(folder)
        self.png = png
        x = particles.mesh.geometry.x
        lo, hi = x.min(axis=0, initial=np.inf), x.max(axis=0, initial=-np.inf)
        particles.comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
        particles.comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
        self.bounds = np.array([lo, hi])
        self.comm = particles.comm
        self.frame = 0
        self.rows = 0  # energies.csv rows written
        self.part = 0  # continuations of the run
        self._times: list[tuple[int, float]] = []  # (frame, time) of the frames written (rank 0)
        self._csv = None
        self._stress_vtx = None
        make_folder(self.folder, self.comm, keep=resume is not None, overwrite=overwrite)
        if resume is not None:
            self.frame, self.rows, self.part = int(resume["frame"]), int(resume["rows"]), int(resume["part"]) + 1
            if self.comm.rank == 0:
                self._truncate()
            self.comm.Barrier()
        self.V = V
        self._velocity: GridSeries | None = None  # made on first use: only the fields written
        self._stress: GridSeries | None = None

    def _grid_name(self, stem: str) -> str:
        return f"{stem}.pvd" if self.part == 0 else f"{stem}_part{self.part}.pvd"

    def _truncate(self) -> None:
        """Drop what the continued run wrote after its checkpoint: energies.csv rows, frame
        times and particle frames."""
        times = self.folder / "particles" / "times.csv"
        for path, keep in ((self.folder / "energies.csv", 1 + self.rows), (times, self.frame)):
            if path.exists():
                path.write_text("".join(path.read_text().splitlines(keepends=True)[:keep]))
        if times.exists():
            self._times = [(int(k), float(tk)) for k, tk in (line.split(",") for line in times.read_text().splitlines())]
        for frame in (self.folder / "particles").glob("particles_*.*vtu"):
            if int(frame.stem.split("_")[1]) >= self.frame:
                frame.unlink()

    def state(self) -> dict:
        """What a continuation needs (:mod:`fempm.checkpoint`)."""
        return {"frame": self.frame, "rows": self.rows, "part": self.part}

    def energies(self, row: dict) -> None:
        self.rows += 1
        if self.comm.rank != 0:
            return
        if self._csv is None:
            path = self.folder / "energies.csv"
            append = self.rows > 0 and path.exists()
            self._file = open(path, "a" if append else "w", newline="")
            self._csv = csv.DictWriter(self._file, fieldnames=list(row))
            if not append:
                self._csv.writeheader()
        self._csv.writerow(row)
        self._file.flush()

    def particles(self, particles: Particles, t: float) -> None:
        """A particle frame at time ``t``, written in parallel (:mod:`fempm.vtu`): each rank's
        piece ``particles/particles_NNNNN_rRRRRR.vtu``, their index ``particles_NNNNN.pvtu``
        and the time collection ``particles.pvd``; the frame's time in ``particles/times.csv``.
        Point data: velocity, stress (9 components), J, id, body and every other scalar or vector
        field (the laws' internal variables, ``volume0``, ``X0``). Collective."""
        f = particles.fields
        n = len(particles)
        x = _pad3(particles.x)
        data = {"velocity": _pad3(f["v"]), "stress": _pad3(f["sigma"]).reshape(n, 9), "J": np.linalg.det(f["F"]),
                "id": particles.ids.astype(np.int64), "body": f["body"].astype(np.int32)}
        for name, a in f.items():  # the laws' internal variables and other per-particle fields
            if name not in ("v", "sigma", "F", "body") and a.ndim in (1, 2) and a.dtype == np.float64:
                data[name] = a
        folder, stem = self.folder / "particles", f"particles_{self.frame:05d}"
        ranks = [r for r, c in enumerate(self.comm.allgather(n)) if c] or [0]  # ranks holding particles
        if self.comm.rank in ranks:
            vtu.write_piece(folder / f"{stem}_r{self.comm.rank:05d}.vtu", x, data)
        if self.comm.rank == 0:
            vtu.write_index(folder / f"{stem}.pvtu", [f"{stem}_r{r:05d}.vtu" for r in ranks], x, data)
            with open(folder / "times.csv", "a") as fh:
                fh.write(f"{self.frame},{float(t)!r}\n")  # a plain number, not np.float64(...)
            self._times.append((self.frame, float(t)))
            vtu.write_collection(self.folder / "particles.pvd",
                                 [(tk, f"particles/particles_{k:05d}.pvtu") for k, tk in self._times])
        if self.png:  # a picture of all particles: gathered
            parts = self.comm.gather((x, np.linalg.norm(data["velocity"], axis=1)), root=0)
            if self.comm.rank == 0:
                from fempm.plot import plot_particle_frame

                plot_particle_frame(np.concatenate([q[0] for q in parts]), np.concatenate([q[1] for q in parts]),
                                    self.folder / "frames" / f"frame_{self.frame:05d}.png", title=f"t = {t:.4g}",
                                    label="|velocity|", bounds=self.bounds)
        self.frame += 1

    def grid(self, v: npt.NDArray | None, t: float, stress: dolfinx.fem.Function | None = None) -> None:
        """Grid velocity (``grid_velocity.pvd``) and grid stress (``grid_stress.pvd``), those
        given, at time ``t`` (:class:`GridSeries`). Collective."""
        if self.V is None:
            return
        if v is not None:
            if self._velocity is None:
                self._velocity = GridSeries(self.V, self.folder / self._grid_name("grid_velocity"))
            self._velocity.write(v.ravel(), t)
        if stress is not None:
            if self._stress is None:
                self._stress = GridSeries(stress.function_space, self.folder / self._grid_name("grid_stress"))
            self._stress.write(stress.x.array, t)

    def summary(self, data: dict) -> None:
        """``summary.json``, written by rank 0; every rank returns once it is on disk (a script
        on any rank may read it next). Collective."""
        if self.comm.rank == 0:
            (self.folder / "summary.json").write_text(json.dumps(data, indent=2, default=float))
        self.comm.barrier()

    def close(self) -> None:
        for series in (self._velocity, self._stress):
            if series is not None:
                series.close()
        if self.comm.rank == 0 and self._csv is not None:
            self._file.close()
