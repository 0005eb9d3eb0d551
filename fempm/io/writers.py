"""Output as a run goes: energies CSV (flushed every row), particle frames as VTKHDF, one file
per frame for all ranks (:mod:`fempm.io.vtkhdf`, :class:`PointFileSeries`; or as VTK XML,
``frame_format="vtu"``), grid fields as VTK XML time series written by every rank in parallel
(:mod:`fempm.io.vtu`, :class:`FrameSeries`), and a JSON summary.

A run's folder holds ``energies.csv``, ``summary.json``, the collections ``particles.pvd``,
``grid_velocity.pvd`` and ``grid_stress.pvd``, and their files in ``particles/`` and ``grid/``.
Every collection is rewritten with each frame, so that a run killed at any moment leaves series
that ParaView reads; a continued run (:mod:`fempm.io.checkpoint`) drops what was written after its
checkpoint and goes on with the same series, so that they equal the uninterrupted run's.

Writing is collective: a rank that cannot write its piece makes every rank raise
:class:`OutputWriteError` naming it, instead of leaving the others waiting.
"""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import dolfinx.fem
import dolfinx.plot
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.io import vtu
from fempm.io.series import FRAME_FORMATS, FrameSeries, OutputWriteError, PointFileSeries, everywhere, vtk_layout
from fempm.io.plot import plot_particle_frame
from fempm.particles.particle_set import Particles

__all__ = ["FRAME_FORMATS", "GRID_FIELDS", "OUTPUT_FILES", "OUTPUT_LIMIT", "FrameSeries", "GridField",
           "OutputFolderError", "OutputSizeError", "OutputWriteError", "PointFileSeries", "RunWriter",
           "check_output_size", "earlier_outputs", "frame_bytes", "frame_format_of", "make_folder", "write_json"]


def determinants(F: npt.NDArray) -> npt.NDArray:
    """det F of (n, d, d) matrices, d <= 3, in closed form (10x numpy.linalg.det's speed on small
    matrices; the same to round-off)."""
    d = F.shape[1]
    if d == 1:
        return F[:, 0, 0].copy()
    if d == 2:
        return F[:, 0, 0] * F[:, 1, 1] - F[:, 0, 1] * F[:, 1, 0]
    return (F[:, 0, 0] * (F[:, 1, 1] * F[:, 2, 2] - F[:, 1, 2] * F[:, 2, 1])
            - F[:, 0, 1] * (F[:, 1, 0] * F[:, 2, 2] - F[:, 1, 2] * F[:, 2, 0])
            + F[:, 0, 2] * (F[:, 1, 0] * F[:, 2, 1] - F[:, 1, 1] * F[:, 2, 0]))


class OutputFolderError(OSError):
    """The output folder cannot be created or written (raised on every rank alike)."""


#: the grid fields a run can write (:attr:`fempm.scene.Scene.outputs`)
GRID_FIELDS = ("grid_velocity", "grid_stress")

#: what a run writes into its output folder (glob patterns)
OUTPUT_FILES = ("summary.json", "energies.csv", "particles", "particles.pvd", "frames", "grid", "grid_velocity*",
                "grid_stress*", "checkpoint", "checkpoint.prev", "checkpoint.old", "checkpoint.tmp")


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


def write_json(path: Path, data: dict) -> None:
    """``data`` as JSON into ``path``, atomically (a complete file or the one before; numpy
    numbers as plain ones). Local: any rank may call it."""
    vtu.write_atomic(path, json.dumps(data, indent=2, default=float))


#: a run whose outputs would exceed this many bytes stops before it starts, unless allowed
#: (:func:`fempm.scene.run`'s ``output_limit``, the command line's ``--force``)
OUTPUT_LIMIT = 2e9


class OutputSizeError(ValueError):
    """A run's outputs would exceed the allowed size (raised on every rank alike, before the
    run writes anything)."""


def frame_bytes(particles: Particles, V: dolfinx.fem.FunctionSpace | None, outputs: tuple[str, ...],
                frame_format: str = "vtkhdf") -> int:
    """The bytes of one frame of ``outputs`` (:data:`fempm.scene.OUTPUTS`) over all ranks: the
    particle frame (position, velocity, stress, J, id, body and the other float fields; raw in
    VTKHDF, base64-encoded in VTK XML, ``frame_format``) and the grid pieces (points, cells and
    values), base64-encoded as :mod:`fempm.io.vtu` writes them. Collective."""
    raw, encoded = 0, 0  # bytes written as they are, bytes base64-encoded (4/3 as many)
    if "particles" in outputs:
        n = len(particles)
        per = 8 * (3 + 3 + 9 + 1 + 1) + 4
        per += sum(8 * int(np.prod(a.shape[1:])) for k, a in particles.fields.items()
                   if k not in ("v", "sigma", "F", "body") and a.ndim in (1, 2) and a.dtype == np.float64)
        frame = n * (per + 8 + 8 + 1)  # + the vertex cells
        if frame_format == "vtkhdf":
            raw += frame
        else:
            encoded += frame
    grids = [name for name in GRID_FIELDS if name in outputs]
    if grids and V is not None:
        points = V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts
        cells = V.mesh.topology.index_map(V.mesh.topology.dim).size_local
        k = V.dofmap.dof_layout.num_dofs
        for name in grids:
            encoded += points * 8 * (3 + (3 if name == "grid_velocity" else 9)) + cells * (8 * k + 8 + 1)
    raw, encoded = particles.comm.allreduce(np.array([raw, encoded]))
    return int(raw + encoded * 4 / 3)


def check_output_size(particles: Particles, V, outputs: tuple[str, ...], frames: int,
                      limit: float | None = OUTPUT_LIMIT, frame_format: str = "vtkhdf") -> int:
    """The estimated bytes of a run's frames (:func:`frame_bytes` times the frames: ``frames``
    over the run, at least one, and the final state); an :class:`OutputSizeError` above
    ``limit`` (None: no limit). Collective."""
    total = frame_bytes(particles, V, outputs, frame_format) * (max(frames, 1) + 1)
    if limit is not None and total > limit:
        raise OutputSizeError(f"the run would write about {total / 1e9:.3g} GB of frames ({max(frames, 1) + 1} frames of "
                              f"{total / (max(frames, 1) + 1) / 1e6:.3g} MB: {particles.num_global} particles"
                              f"{' and the grid fields' if any(g in outputs for g in GRID_FIELDS) else ''}), more than "
                              f"the {limit / 1e9:g} GB allowed: give fewer frames (--frames), or --force "
                              "(output_limit=None) to write them")
    return total


class GridField:
    """What the VTK pieces of a Lagrange field of ``V`` need: this rank's cells and dof points
    (:func:`dolfinx.plot.vtk_mesh`: VTK Lagrange cells of the space's degree) and its values
    at them. A field of a variant whose dofs are not point values (Bernstein) is interpolated
    into the standard Lagrange space of the same degree, which holds it exactly."""

    def __init__(self, V: dolfinx.fem.FunctionSpace):
        self.shape = tuple(V.value_shape)
        self._source = self._target = None
        if not V.element.interpolation_ident:
            el = V.element.basix_element
            self._target = dolfinx.fem.Function(dolfinx.fem.functionspace(V.mesh, ("Lagrange", el.degree, self.shape)))
            self._source = dolfinx.fem.Function(V)
            V = self._target.function_space
        topology, types, self.points = dolfinx.plot.vtk_mesh(V)
        self.cells = (topology.reshape(len(types), -1)[:, 1:], types)

    def values(self, local: npt.NDArray) -> npt.NDArray:
        """The point data (points, 3) of a vector or (points, 9) of a tensor field from its
        local dof values (owned and ghost, blocked); collective for a Bernstein field."""
        if self._source is not None:
            self._source.x.array[:] = np.ravel(local)
            self._target.interpolate(self._source)
            local = self._target.x.array
        a = np.asarray(local).reshape(len(self.points), *self.shape)
        return vtk_layout(a)


def frame_format_of(resume: dict | None, frame_format: str) -> str:
    """The particle frames' format of a run's writer: a continued run's own (``resume``, the
    writer state in its checkpoint; VTK XML for checkpoints from before VTKHDF frames), else
    ``frame_format``."""
    return resume.get("frame_format", "vtu") if resume is not None else frame_format


class RunWriter:
    """Writes a run's outputs into ``folder`` as the run goes (nothing kept only in memory)."""

    def __init__(self, folder: Path, particles: Particles, V: dolfinx.fem.FunctionSpace | None = None,
                 *, png: bool = False, resume: dict | None = None, overwrite: bool = True,
                 frame_format: str = "vtkhdf"):
        """``resume``: the :meth:`state` of the writer of the run being continued (from its
        checkpoint): the energies and frames written after it are dropped and the series go on
        from its frame count, in its frame format. Otherwise the outputs of an earlier run in
        ``folder`` are removed with ``overwrite``, else refused (:func:`make_folder`).
        ``frame_format``: the particle frames' format, of :data:`FRAME_FORMATS`. Collective."""
        frame_format = frame_format_of(resume, frame_format)
        if frame_format not in FRAME_FORMATS:
            raise ValueError(f"unknown frame_format={frame_format!r}; expected one of {', '.join(FRAME_FORMATS)}")
        self.frame_format = frame_format
        self.folder = Path(folder)
        self.png = png
        x = particles.mesh.geometry.x
        lo, hi = x.min(axis=0, initial=np.inf), x.max(axis=0, initial=-np.inf)
        particles.comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
        particles.comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
        self.bounds = np.array([lo, hi])
        self.comm = particles.comm
        self.frame = 0  # frames written (particles, grid fields or both: one numbering)
        self.rows = 0  # energies.csv rows written
        self._csv = None
        make_folder(self.folder, self.comm, keep=resume is not None, overwrite=overwrite)
        self._particles = FRAME_FORMATS[frame_format](self.folder, "particles", "particles", self.comm,
                                                      times=self.folder / "particles" / "times.csv")
        self._grid = {stem: FrameSeries(self.folder, "grid", stem, self.comm) for stem in GRID_FIELDS}
        self._fields: dict[str, GridField] = {}  # made on first use: only the fields written
        self.V = V
        if resume is not None:
            self.frame, self.rows = int(resume["frame"]), int(resume["rows"])
            if self.comm.rank == 0:
                self._truncate()
            self.comm.Barrier()

    def _truncate(self) -> None:
        """Drop what the continued run wrote after its checkpoint: energies.csv rows, frames of
        every series and PNG frames, and the temporary files of writes a killed run left
        unfinished (:func:`fempm.io.vtu.write_atomic`'s ``.NAME.PID.tmp``) (rank 0)."""
        for tmp in self.folder.rglob(".*.tmp"):
            if tmp.is_file():
                tmp.unlink()
        energies = self.folder / "energies.csv"
        if energies.exists():
            lines = energies.read_bytes().split(b"\n")
            energies.write_bytes(b"".join(line + b"\n" for line in lines[: 1 + self.rows] if line))
        for series in (self._particles, *self._grid.values()):
            series.truncate(self.frame)
        for png in (self.folder / "frames").glob("frame_*.png"):
            if int(png.stem.split("_")[1]) >= self.frame:
                png.unlink()

    def state_dict(self) -> dict:
        """What a continuation needs (:mod:`fempm.io.checkpoint`; given back as ``resume``)."""
        return {"frame": self.frame, "rows": self.rows, "frame_format": self.frame_format}

    def energies(self, row: dict) -> None:
        """One row of ``energies.csv`` (rank 0 writes; LF line ends; flushed)."""
        self.rows += 1
        if self.comm.rank != 0:
            return
        if self._csv is None:
            path = self.folder / "energies.csv"
            append = path.exists() and path.stat().st_size > 0  # a continued run's
            self._file = open(path, "a" if append else "w", newline="")
            self._csv = csv.DictWriter(self._file, fieldnames=list(row), lineterminator="\n")
            if not append:
                self._csv.writeheader()
        self._csv.writerow(row)
        self._file.flush()

    def write_frame(self, t: float, particles: Particles | None = None, velocity: npt.NDArray | None = None,
                    stress: dolfinx.fem.Function | None = None) -> None:
        """One frame at time ``t`` of what is given: the particles, the grid velocity (local
        dof values of the writer's space) and the grid stress. Collective; a frame that fails
        keeps its number (the next frame takes the next one)."""
        try:
            if particles is not None:
                self._write_particles(particles, t)
            if velocity is not None and self.V is not None:
                self._write_grid("grid_velocity", self.V, velocity, t)
            if stress is not None:
                stress.x.scatter_forward()
                self._write_grid("grid_stress", stress.function_space, stress.x.array, t)
        finally:
            self.frame += 1

    def _write_grid(self, stem: str, V: dolfinx.fem.FunctionSpace, values: npt.NDArray, t: float) -> None:
        if stem not in self._fields:
            self._fields[stem] = GridField(V)
        field = self._fields[stem]
        self._grid[stem].write(self.frame, t, field.points, {stem: field.values(values)}, field.cells)

    def _write_particles(self, particles: Particles, t: float) -> None:
        """The particle frame: point data velocity, stress (9 components), J, id, body and every
        other scalar or vector field (the laws' internal variables, ``volume0``, ``X0``)."""
        f = particles.fields
        data = {"velocity": f["v"], "stress": f["sigma"], "J": determinants(f["F"]),
                "id": particles.ids.astype(np.int64, copy=False), "body": f["body"].astype(np.int32, copy=False)}
        for name, a in f.items():  # the laws' internal variables and other per-particle fields
            if name not in ("v", "sigma", "F", "body") and a.ndim in (1, 2) and a.dtype == np.float64:
                data[name] = a
        self._particles.write_points(self.frame, t, particles.x, data, vectors=("velocity",))
        if self.png:  # a picture of all particles: gathered
            parts = self.comm.gather((vtk_layout(particles.x), np.linalg.norm(f["v"], axis=1)), root=0)
            if self.comm.rank == 0:
                plot_particle_frame(np.concatenate([q[0] for q in parts]), np.concatenate([q[1] for q in parts]),
                                    self.folder / "frames" / f"frame_{self.frame:05d}.png", title=f"t = {t:.4g}",
                                    label="|velocity|", bounds=self.bounds)

    def summary(self, data: dict) -> None:
        """``summary.json``, written by rank 0 (atomically); every rank returns once it is on
        disk (a script on any rank may read it next). Collective."""
        everywhere(self.comm, "summary.json", lambda: write_json(self.folder / "summary.json", data), root_only=True)

    def close(self) -> None:
        """Close the energies file (local: any rank may call it, also after a failure)."""
        if self._csv is not None:
            self._file.close()
            self._csv = None
