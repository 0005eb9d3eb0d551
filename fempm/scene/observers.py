"""The run loop's observers: each part of a run that is not the step itself (frames, the
energies file, the health checks, the scene's watch and the caller's callback, checkpoints and
signals, the progress bar) is an :class:`Observer` called before and after every step, in the
order :func:`fempm.scene.run` lists them."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Protocol

from mpi4py import MPI

from fempm.io import stops
from fempm.io.writers import RunWriter
from fempm.stepping.health import HealthMonitor
from fempm.stepping.solver import ExplicitSolver
from fempm.timings import Timings

__all__ = ["Checkpoints", "Energies", "Frames", "HealthChecks", "Observer", "Progress", "Run", "Watch"]


class Run(Protocol):
    """What the observers read of a run (:class:`fempm.scene.loop.Run` is one).

    Attributes:
        solver: The scene's solver.
        writer: Its outputs (None: a run without an output folder).
        monitor: The run-health checks.
        history: The energies rows so far.
        momentum_scale: The last step's sum of the particles' |momentum| (the health checks').
        out: The output folder (None: none).
        comm: The run's communicator.
        timings: The seconds of the run's phases on this rank (:mod:`fempm.timings`).
    """

    solver: ExplicitSolver
    writer: RunWriter | None
    monitor: HealthMonitor
    history: list[dict]
    momentum_scale: float | None
    out: Path | None
    comm: MPI.Comm
    timings: Timings

    def save(self) -> Path:
        """A checkpoint of the state now (collective)."""

    def write_frame(self) -> None:
        """A frame of the state now (collective)."""


class Observer:
    """A part of the run loop (the default does nothing)."""

    def before_step(self, run: Run) -> None:
        """Called before each step (the state at ``run.solver.t``)."""

    def after_step(self, run: Run, dt: float, row: dict, final: bool) -> None:
        """Called after each step of ``dt``; ``row``: the step's energies row; ``final``: the
        step reached ``t_end``."""


class Frames(Observer):
    """The frames the scene asks for, every ``t_end / frames`` (collective)."""

    def __init__(self, interval: float, next_frame: float = 0.0):
        self.interval, self.next_frame = interval, next_frame

    def before_step(self, run: Run) -> None:
        if run.writer is not None and run.solver.t >= self.next_frame:
            run.write_frame()
            self.next_frame += self.interval


class Energies(Observer):
    """The energies row of every step into the run's history and ``energies.csv``."""

    def after_step(self, run: Run, dt: float, row: dict, final: bool) -> None:
        run.history.append(row)
        if run.writer is not None:
            with run.timings.phase("output_s"):
                run.writer.energies(row)


class HealthChecks(Observer):
    """The scene's health limits (:class:`fempm.stepping.health.HealthMonitor`; collective)."""

    def after_step(self, run: Run, dt: float, row: dict, final: bool) -> None:
        run.monitor.after_step(dt, row, final=final, momentum_scale=run.momentum_scale)


class Watch(Observer):
    """A callable of the solver after every step (the scene's ``watch``, the caller's ``callback``)."""

    def __init__(self, fn: Callable):
        self.fn = fn

    def after_step(self, run: Run, dt: float, row: dict, final: bool) -> None:
        self.fn(run.solver)


class Checkpoints(Observer):
    """A checkpoint every ``every`` steps and at the end of a checkpointed or resumed run; a
    requested stop (SIGTERM, SIGINT: ``stop``) ends the run after a checkpoint (collective)."""

    def __init__(self, every: int | None, at_end: bool, stop):
        self.every, self.at_end, self.stop = every, at_end, stop

    def after_step(self, run: Run, dt: float, row: dict, final: bool) -> None:
        step = run.solver.step_count
        if (self.every is not None and step % self.every == 0) or (self.at_end and final):
            run.save()
        if run.out is not None and (signum := stops.requested(self.stop, run.comm)):
            raise stops.RunInterrupted(signum, run.solver.t, run.save())


class Progress(Observer):
    """The progress bar (rank 0, on a terminal)."""

    def __init__(self, bar):
        self.bar = bar

    def after_step(self, run: Run, dt: float, row: dict, final: bool) -> None:
        if not self.bar.disable:
            self.bar.set_postfix_str(f"step {run.solver.step_count}, dt = {dt:.3g}", refresh=False)
            self.bar.update(run.solver.t - self.bar.n)
