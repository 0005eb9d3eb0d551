"""A scene is data (mesh, particles with a body index, materials, boundary conditions, loads,
transfer options, outputs); :func:`run` builds the explicit solver for exactly what the scene
declares and writes its outputs as it goes."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from pathlib import Path

from mpi4py import MPI
from tqdm import tqdm

from fempm.abort import FailureAgreement, abort
from fempm.io import checkpoint, stops
from fempm.io.writers import (FRAME_FORMATS, OUTPUT_LIMIT, RunWriter, check_output_size, frame_format_of,
                               write_json)
from fempm.particles.location import OutsideMeshError
from fempm.scene.definition import MAX_STEPS, Scene
from fempm.scene.observers import Checkpoints, Energies, Frames, HealthChecks, Observer, Progress, Watch
from fempm.stepping.health import HealthMonitor
from fempm.stepping.options import SimulationError
from fempm.stepping.solver import ExplicitSolver
from fempm.timings import Timings, line
from fempm.transfer.mapping import SingularMassError

__all__ = ["RUN_STATS", "Run", "outcome_of", "run", "run_stats", "write_frame"]

#: the run summary's cost figures that demos report with their own results
RUN_STATS = ("steps", "particles", "particle_steps_per_s", "terms_assembled")


def run_stats(summary: dict) -> dict:
    """The :data:`RUN_STATS` entries of a :func:`run` summary."""
    return {k: summary[k] for k in RUN_STATS}


def write_frame(writer: RunWriter, scene: Scene, solver: ExplicitSolver, *, grid: bool = True,
                particles: bool = False) -> None:
    """The frames the scene asks for at the solver's time (collective); ``particles`` writes the
    particles' in any case (a run's final or failing state)."""
    outputs = scene.outputs
    grid = grid and ("grid_velocity" in outputs or "grid_stress" in outputs)
    velocity = None
    if grid and "grid_velocity" in outputs:
        velocity = solver.grid_velocity if solver.grid_velocity is not None else solver.mapped_velocity()
    writer.write_frame(solver.t, scene.particles if particles or "particles" in outputs else None, velocity,
                       solver.grid_stress() if grid and "grid_stress" in outputs else None)


#: how a run that raised ends (``status`` in its summary): stopped by a health limit or a failed
#: step (the state may not be finite), interrupted by a signal after a checkpoint, or failed
#: otherwise (an error in a law, a callback, an output)
ABORTED, INTERRUPTED, FAILED = "aborted", "interrupted", "failed"


def outcome_of(error: BaseException) -> str:
    """The ``status`` of a run that raised ``error``."""

    if isinstance(error, (SimulationError, SingularMassError, OutsideMeshError)):
        return ABORTED
    if isinstance(error, (stops.RunInterrupted, KeyboardInterrupt)):
        return INTERRUPTED
    return FAILED


def run(
    scene: Scene,
    out: Path | None = None,
    *,
    progress: bool = True,
    png: bool = False,
    callback: Callable[[ExplicitSolver], None] | None = None,
    checkpoint_every: int | None = None,
    resume: bool = False,
    rebuild: dict | None = None,
    overwrite: bool = True,
    output_limit: float | None = OUTPUT_LIMIT,
    frame_format: str = "vtkhdf",
) -> dict:
    """Run ``scene`` to ``t_end``, writing its outputs as it goes.

    Energies and momentum are recorded every step (returned in ``history``; with ``out``
    written to ``energies.csv`` as the run goes, with the particle frames, the grid velocity
    and stress (particles as VTKHDF or VTK XML, grid fields as VTK XML; the stress projected as a per-volume field,
    :meth:`ExplicitSolver.grid_stress`), ``summary.json`` and, with ``png``, a PNG of the
    particles per frame in ``frames/``; :mod:`fempm.io`). The scene's
    :class:`~fempm.stepping.health.Health` limits are checked every step.

    A run that raises still writes its summary (``status`` "aborted" for a health limit or a
    failed step: J <= 0, non-finite state, singular mass, a particle leaving the mesh;
    "interrupted"; "failed" for any other error, ``health.error`` the message) and a particle
    frame of its last state, then raises the error. With ``out``, SIGTERM and SIGINT stop the
    run at the next step boundary after a checkpoint, its summary (``status`` "interrupted")
    and a particle frame.

    Args:
        scene: What to run.
        out: The output folder (None: nothing written).
        progress: Print a progress bar (and the estimated output size).
        png: Also write a PNG of the particles per frame.
        callback: Called with the solver after every step (collective).
        checkpoint_every: With ``out``, write the full state to ``out/checkpoint/`` every that
            many steps and at the end (:mod:`fempm.io.checkpoint`).
        resume: Continue the run whose checkpoint is in ``out`` (``scene`` built as it was,
            with the ``t_end`` to run to); on the same number of ranks the continuation writes
            byte for byte what the uninterrupted run writes.
        rebuild: How to build ``scene`` again (the command line's scene name and options), kept
            in the checkpoint for ``python -m fempm resume``.
        overwrite: Remove the outputs of an earlier run in ``out`` (else they are an error).
        output_limit: The bytes of frames a run may write, estimated before it starts (None:
            no limit).
        frame_format: The particle frames' format: ``"vtkhdf"``, one file per frame for all
            ranks (:mod:`fempm.io.vtkhdf`), or ``"vtu"``, VTK XML, a piece per rank (a resumed
            run keeps its checkpoint's).

    Returns:
        The summary (as in ``summary.json``) with the energy ``history``.

    Raises:
        fempm.SimulationError: A health limit or a failed step (after the summary is written).
        fempm.io.stops.RunInterrupted: SIGTERM or SIGINT (after the checkpoint).
        fempm.io.checkpoint.CheckpointError: ``resume`` with a damaged checkpoint or a scene
            that differs from the checkpoint's, naming the difference.
        fempm.io.OutputSizeError: Frames larger than ``output_limit``, before anything is
            written.

    Note:
        Collective. An error raised on some ranks only (a law, ``Scene.watch`` or ``callback``
        failing on one rank, a file it cannot write) would leave the others waiting in a
        collective call: the failing rank writes the summary alone (``status`` "failed", the
        error with its rank) and ends every rank (:func:`fempm.abort.abort`, exit code 1)
        within seconds (:class:`fempm.abort.FailureAgreement`).
    """
    if (checkpoint_every is not None or resume) and out is None:
        raise ValueError("checkpoints need an output folder (out)")
    if frame_format not in FRAME_FORMATS:
        raise ValueError(f"unknown frame_format={frame_format!r}; expected one of {', '.join(FRAME_FORMATS)}")
    if scene.options.integration is not None and scene.dt is None:
        raise ValueError("an implicit run takes fixed steps: give the scene a dt (Scene(dt=...), or --steps N on the "
                         "command line); the CFL condition does not bound it")
    if checkpoint_every is not None and (isinstance(checkpoint_every, bool) or int(checkpoint_every) != checkpoint_every
                                         or checkpoint_every < 1):
        raise ValueError(f"checkpoint_every={checkpoint_every!r} must be a positive number of steps")
    return Run(scene, None if out is None else Path(out), png=png, resume=resume, overwrite=overwrite,
                checkpoint_every=checkpoint_every, rebuild=rebuild, output_limit=output_limit,
                progress=progress, frame_format=frame_format).execute(progress, callback)


class Run:
    """One call of :func:`run`: the solver, the writer and the monitor of a scene, the loop and
    how it ends."""

    def __init__(self, scene: Scene, out: Path | None, *, png: bool, resume: bool, overwrite: bool,
                 checkpoint_every: int | None, rebuild: dict | None, output_limit: float | None, progress: bool,
                 frame_format: str = "vtkhdf"):

        self.scene, self.out, self.every, self.resumed, self.rebuild = scene, out, checkpoint_every, resume, rebuild
        self.comm = comm = scene.mesh.comm
        # the particles the scene starts with (a resumed run's as its first part's: some may have
        # left the mesh since, and the checkpoint holds only the survivors)
        self.num_particles = scene.particles.num_global
        self.timings = timings = Timings()
        timings.add(scene.timings)
        saved, arrays = None, {}
        if resume:
            with timings.phase("checkpoint_s"):
                saved, arrays = checkpoint.restore_particles(out, scene, comm)
        with timings.phase("solver_s"):
            self.solver = solver = scene.solver()
        if saved is not None:
            checkpoint.check_fields(saved, scene.particles, comm)
        if out is not None:
            size = check_output_size(scene.particles, solver.V, scene.outputs, scene.frames, output_limit,
                                     frame_format_of(saved["writer"] if saved else None, frame_format))
            if progress and comm.rank == 0:
                print(f"{scene.name}: about {size / 1e6:.3g} MB of frames into {out}")
        self.writer = (RunWriter(out, scene.particles, solver.V, png=png, resume=saved["writer"] if saved else None,
                                 overwrite=overwrite, frame_format=frame_format) if out is not None else None)
        self.monitor = HealthMonitor(solver, scene.health)
        self.history = [solver.energies()]
        self.frames = Frames(scene.t_end / max(scene.frames, 1))
        if saved is None and callable(getattr(scene.watch, "start", None)):
            scene.watch.start(solver)
        if saved is not None:
            with timings.phase("checkpoint_s"):
                checkpoint.restore_solver(solver, self.monitor, saved, arrays)
            checkpoint.restore_watch(scene.watch, saved)
            self.history[0] = saved["writer"]["initial"]
            self.frames = Frames(saved["writer"]["frame_interval"], saved["writer"]["next_frame"])
            if solver.t >= scene.t_end:
                raise ValueError(f"the run in {out} is already at t = {solver.t:.6g}: give a later t_end")
        self.steps0 = solver.step_count
        self.momentum_scale: float | None = None  # the last step's sum_p M_p |v_p|, for the health checks
        self.agreement = FailureAgreement(comm)

    def save(self) -> Path:
        """A checkpoint of the state now (collective)."""

        state = {**self.writer.state_dict(), "next_frame": self.frames.next_frame, "frame_interval": self.frames.interval,
                 "initial": self.history[0]}
        with self.timings.phase("checkpoint_s"):
            return checkpoint.write(self.out, self.scene, self.solver, self.monitor, state, self.rebuild)

    def step(self) -> float:
        """One step to at most ``t_end`` (the scene's fixed ``dt`` or the stable one); the
        last step ends exactly at ``t_end``. Returns the step's ``dt``."""
        scene, solver = self.scene, self.solver
        remaining = scene.t_end - solver.t
        with self.timings.phase("first_step_s" if solver.step_count == self.steps0 else "steps_s"):
            if scene.dt is None:
                dt = solver.step(dt_max=remaining, totals=True)
            else:  # a last step shorter than 1e-9 dt is merged into the one before
                dt = solver.step(remaining if remaining <= scene.dt * (1 + 1e-9) else scene.dt, totals=True)
        final = dt >= remaining
        if not final and remaining > MAX_STEPS * dt:  # e.g. velocities of 1e200: no progress
            raise SimulationError(f"step {solver.step_count}, t = {solver.t:.6g}: time step collapse: dt = {dt:.3g} "
                                  f"would need more than {MAX_STEPS:.0e} steps to reach t_end = {scene.t_end:g}")
        if final:  # the final step: end exactly at t_end
            solver.t = scene.t_end
        return dt

    def write_frame(self) -> None:
        """The frames the scene asks for at the solver's time (collective)."""
        with self.timings.phase("output_s"):
            write_frame(self.writer, self.scene, self.solver)

    def observers(self, bar, stop, callback) -> list[Observer]:
        """The loop's observers, in the order they are called."""
        watches = [Watch(fn) for fn in (self.scene.watch, callback) if fn is not None]
        checkpoints = Checkpoints(self.every, self.every is not None or self.resumed, stop)
        return [self.frames, Energies(), HealthChecks(), *watches, checkpoints, Progress(bar)]

    def loop(self, observers: list[Observer]) -> None:
        """Step to ``t_end``, the observers before and after every step."""
        scene, solver = self.scene, self.solver
        while solver.t < scene.t_end:
            for observer in observers:
                observer.before_step(self)
            dt = self.step()
            final = solver.t >= scene.t_end
            energies, self.momentum_scale = solver.step_energies()  # from the step's own sums where it keeps them
            row = {"step": solver.step_count, "dt": dt, **energies}
            for observer in observers:
                observer.after_step(self, dt, row, final)

    def execute(self, progress: bool, callback) -> dict:
        """The loop, then the final frame and the summary, also when the loop raised (the error
        is raised after them)."""

        comm, solver = self.comm, self.solver
        t0 = time.perf_counter()
        failure: BaseException | None = None
        # the progress bar: rank 0, only on a terminal (tqdm's disable=None)
        bar = tqdm(total=self.scene.t_end, initial=solver.t, disable=None if progress and comm.rank == 0 else True,
                   unit="", bar_format="{l_bar}{bar}| t = {n:.4g} / {total:g} [{elapsed}<{remaining}{postfix}]",
                   leave=False)
        try:
            with bar, stops.stop_requests(comm) if self.out is not None else contextlib.nullcontext([0]) as stop:
                self.loop(self.observers(bar, stop, callback))
            self.monitor.outcome = "completed"
        except (Exception, KeyboardInterrupt) as e:
            failure = e
            self.settle(e, t0)
            self.monitor.outcome, self.monitor.error = outcome_of(e), str(e)
        self.final_frame(t0)
        summary = self.summary(time.perf_counter() - t0, collective=True)
        if self.scene.results is not None and self.monitor.outcome in ("completed", INTERRUPTED):
            summary.update(self.scene.results(self.scene, solver))
        if progress and comm.rank == 0 and failure is None:
            print(f"{self.scene.name}: {solver.step_count} steps to t = {solver.t:.4g} in {summary['wall_time_s']:.2f} s "
                  f"({summary['particle_steps_per_s']:.3g} particle-steps/s; {line(summary['timings'])})")
        if self.writer is not None:
            self.writer.summary(summary)
        self.agreement.free()
        if failure is not None:  # the summary and the frames are written: now stop
            failure.health = {**summary["health"], "steps": solver.step_count}  # for studies that catalogue failures
            raise failure
        summary["history"] = self.history
        summary["solver"] = solver
        return summary

    def settle(self, error: BaseException, t0: float) -> None:
        """After ``error`` on this rank: return if every rank raised (the run can end
        collectively); else write the summary from this rank alone and end every rank."""
        if self.agreement.everyone():
            return
        self.monitor.outcome, self.monitor.error = FAILED, f"rank {self.comm.rank}: {type(error).__name__}: {error}"
        if self.writer is not None:
            self.writer.close()
            with contextlib.suppress(OSError):
                write_json(self.writer.folder / "summary.json", self.summary(time.perf_counter() - t0, collective=False))
        abort(self.comm, f"{type(error).__name__}: {error}")

    def final_frame(self, t0: float) -> None:
        """The final state's frame: the particles, and the grid fields of a run that did not
        fail (collective; an error writing it is settled as the loop's are)."""
        if self.writer is None:
            return
        writing = self.monitor.outcome in ("completed", INTERRUPTED) and self.solver.grid_velocity is not None
        try:
            with self.timings.phase("output_s"):
                write_frame(self.writer, self.scene, self.solver, grid=writing, particles=True)
        except Exception as e:  # noqa: BLE001 - the summary is still written
            self.settle(e, t0)
            self.monitor.error = "; ".join(filter(None, [self.monitor.error, f"the final frame: {e}"]))
        finally:
            self.writer.close()

    def summary(self, wall: float, *, collective: bool) -> dict:
        """The run's summary; ``collective``: the wall time is the slowest rank's (else this
        rank's, for a summary written by one rank)."""
        solver = self.solver
        timings = self.timings.slowest(self.comm) if collective else dict(self.timings.seconds)
        if collective:
            wall = self.comm.allreduce(wall, op=MPI.MAX)
        return {
            "scene": self.scene.name,
            "params": self.scene.params,
            "particles": self.num_particles,
            "steps": solver.step_count,
            "t_end": solver.t,
            "wall_time_s": wall,
            "timings": timings,
            "particle_steps_per_s": self.num_particles * (solver.step_count - self.steps0) / wall if wall > 0 else 0.0,
            "terms_assembled": dict(solver.terms),
            "final": self.history[-1],
            "initial": self.history[0],
            "status": self.monitor.outcome,
            "health": self.monitor.summary(),
            **solver.removal.summary(),
            **solver.collisions.summary(),
        }
