"""A scene is data (mesh, particles with a body index, materials, boundary conditions, loads,
transfer options, outputs); :func:`run` builds the explicit solver for exactly what the scene
declares and writes its outputs as it goes."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import dolfinx.fem
import dolfinx.mesh
import numpy as np
from mpi4py import MPI
from tqdm import tqdm

from fempm.contact import Contact
from fempm.health import Health, HealthMonitor
from fempm.io import RunWriter
from fempm.particles import Particles
from fempm.stepping import ExplicitSolver, Loads, SimulationError, StepOptions
from fempm.transfer import SingularMassError


def check_counts(**counts: int) -> None:
    """Scene builders' counts (cells, particles per cell, frames, ...) must be positive
    integers: a ValueError naming the first that is not."""
    for name, value in counts.items():
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{name}={value!r} must be a positive integer")


#: the frames a scene can ask for (:attr:`Scene.outputs`)
OUTPUTS = ("particles", "grid_velocity", "grid_stress")

#: more steps than this to the end time is a collapsed time step (a run that would not end)
MAX_STEPS = 1e9

@dataclass
class Scene:
    """Everything a run needs.

    ``bcs`` builds the grid conditions from the vector space (``V -> [Fixed | Slip]``).
    ``frames`` particle/grid frames are written over ``[0, t_end]``. ``dt``: a fixed time step
    (the last step is shortened so that the run ends exactly at ``t_end``; a step above the
    stability limit is an error); None (default) takes the CFL step of
    :meth:`ExplicitSolver.stable_dt` every step. ``variant``: the Lagrange variant of the
    velocity space (e.g. ``"bernstein"``, non-negative on simplices), default the DOLFINx one.
    ``health``: the limits that stop an unhealthy run (:class:`fempm.health.Health`: energy
    growth beyond the work of the loads, J bounds, time-step floor). ``outputs``: the frames a
    run with an output folder writes, of :data:`OUTPUTS` (the energies and the summary always);
    what is not asked for is not computed (the grid stress is a projection per frame).
    ``results``: the scene's own measures of the final state, ``results(scene, solver) -> dict``
    (collective), added to the run's summary. ``contact``: one velocity field per particle
    group with frictional contact (:class:`fempm.contact.Contact`); None: one field.
    ``watch``: called with the solver after every step (collective), for the scene's own
    histories (a continued run calls it from the checkpoint on).
    """

    name: str
    mesh: dolfinx.mesh.Mesh
    particles: Particles
    materials: Sequence
    t_end: float
    bcs: Callable[[dolfinx.fem.FunctionSpace], Sequence] | None = None
    loads: Loads = field(default_factory=Loads)
    options: StepOptions = field(default_factory=StepOptions)
    degree: int = 1
    frames: int = 20
    params: dict = field(default_factory=dict)
    dt: float | None = None
    variant: str | None = None
    health: Health = field(default_factory=Health)
    outputs: tuple[str, ...] = OUTPUTS
    results: Callable[[Scene, ExplicitSolver], dict] | None = None
    contact: Contact | None = None
    watch: Callable[[ExplicitSolver], None] | None = None

    def __post_init__(self):
        unknown = set(self.outputs) - set(OUTPUTS)
        if unknown:
            raise ValueError(f"unknown output(s) {sorted(unknown)}; expected some of {OUTPUTS}")
        if not (0.0 < self.t_end < np.inf):
            raise ValueError(f"t_end={self.t_end} must be a positive, finite time")
        if isinstance(self.frames, bool) or not isinstance(self.frames, (int, np.integer)) or self.frames < 0:
            raise ValueError(f"frames={self.frames!r} must be a non-negative integer")
        if self.dt is not None and not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt={self.dt} must be a positive number (or None for the CFL step)")

    def space(self) -> dolfinx.fem.FunctionSpace:
        """The vector Lagrange velocity space of the scene's degree (and variant)."""
        d = self.mesh.geometry.dim
        if self.variant is None:
            return dolfinx.fem.functionspace(self.mesh, ("Lagrange", self.degree, (d,)))
        import basix.ufl

        variant = getattr(basix.LagrangeVariant, self.variant)
        return dolfinx.fem.functionspace(
            self.mesh, basix.ufl.element("Lagrange", self.mesh.basix_cell(), self.degree, variant, shape=(d,)))

    def solver(self) -> ExplicitSolver:
        V = self.space()
        bcs = list(self.bcs(V)) if self.bcs is not None else []
        return ExplicitSolver(V, self.particles, self.materials, bcs=bcs, loads=self.loads, options=self.options,
                              contact=self.contact)


#: the run summary's cost figures that demos report with their own results
RUN_STATS = ("steps", "particles", "particle_steps_per_s", "terms_assembled")


def run_stats(summary: dict) -> dict:
    """The :data:`RUN_STATS` entries of a :func:`run` summary."""
    return {k: summary[k] for k in RUN_STATS}


def write_frame(writer: RunWriter, scene: Scene, solver: ExplicitSolver, *, grid: bool = True,
                particles: bool = False) -> None:
    """The frames the scene asks for at the solver's time (collective); ``particles`` writes the
    particles' in any case (a run's final or failing state)."""
    if particles or "particles" in scene.outputs:
        writer.particles(scene.particles, solver.t)
    if grid and ("grid_velocity" in scene.outputs or "grid_stress" in scene.outputs):
        v = solver.grid_velocity if solver.grid_velocity is not None else solver.mapped_velocity()
        writer.grid(v if "grid_velocity" in scene.outputs else None, solver.t,
                    stress=solver.grid_stress() if "grid_stress" in scene.outputs else None)


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
) -> dict:
    """Run ``scene`` to ``t_end``. Energies and momentum are recorded every step (returned in
    ``history`` and, with ``out``, written to ``energies.csv`` as the run goes, together with
    particle VTK frames, the grid velocity and stress (VTK XML, the stress projected as a per-volume
    field, :meth:`ExplicitSolver.grid_stress`), ``summary.json`` and, with ``png``, a PNG of
    the particles per frame in ``frames/``). The scene's :class:`~fempm.health.Health` limits are
    checked every step; a run that crosses one (or fails otherwise: J <= 0, non-finite state,
    singular mass) still writes its summary (``status`` "aborted", ``health.error``) and a
    particle frame of the failing state, then raises the error.

    ``checkpoint_every``: with ``out``, write the full state to ``out/checkpoint/`` every that
    many steps and at the end (:mod:`fempm.checkpoint`; a resumed run also writes one at its end). With ``out``, SIGTERM and SIGINT stop
    the run at the next step boundary, after a checkpoint, its summary (``status``
    "interrupted") and a particle frame; then :class:`fempm.checkpoint.RunInterrupted` is raised.
    ``resume``: continue the run whose checkpoint is in ``out`` (``scene`` built as it was, with
    the ``t_end`` to run to); on the same number of ranks the continuation is bit for bit the
    uninterrupted run (lumped mass). ``rebuild``: how to build ``scene`` again (the command
    line's scene name and options), kept in the checkpoint for ``python -m fempm resume``.
    ``overwrite``: remove the outputs of an earlier run in ``out`` (else they are an error;
    :func:`fempm.io.make_folder`)."""
    from fempm import checkpoint

    comm = scene.mesh.comm
    if (checkpoint_every is not None or resume) and out is None:
        raise ValueError("checkpoints need an output folder (out)")
    if checkpoint_every is not None and (isinstance(checkpoint_every, bool) or int(checkpoint_every) != checkpoint_every
                                         or checkpoint_every < 1):
        raise ValueError(f"checkpoint_every={checkpoint_every!r} must be a positive number of steps")
    saved, arrays = checkpoint.restore_particles(Path(out), scene, comm) if resume else (None, {})
    solver = scene.solver()
    writer = (RunWriter(Path(out), scene.particles, solver.V, png=png, resume=saved["writer"] if saved else None,
                        overwrite=overwrite) if out is not None else None)
    monitor = HealthMonitor(solver, scene.health)
    history = [solver.energies()]
    frame_interval = scene.t_end / max(scene.frames, 1)
    next_frame = 0.0
    if saved is not None:
        checkpoint.restore_solver(solver, monitor, saved, arrays)
        history[0] = saved["writer"]["initial"]
        next_frame, frame_interval = saved["writer"]["next_frame"], saved["writer"]["frame_interval"]
        if solver.t >= scene.t_end:
            raise ValueError(f"the run in {out} is already at t = {solver.t:.6g}: give a later t_end")

    def save() -> Path:
        state = {**writer.state(), "next_frame": next_frame, "frame_interval": frame_interval, "initial": history[0]}
        return checkpoint.write(Path(out), scene, solver, monitor, state, rebuild)

    steps0 = solver.step_count
    t0 = time.perf_counter()
    failure: Exception | None = None
    # the progress bar: rank 0, only on a terminal (tqdm's disable=None)
    bar = tqdm(total=scene.t_end, initial=solver.t, disable=None if progress and comm.rank == 0 else True, unit="",
               bar_format="{l_bar}{bar}| t = {n:.4g} / {total:g} [{elapsed}<{remaining}{postfix}]", leave=False)
    with bar, checkpoint.stop_requests(comm) if out is not None else contextlib.nullcontext([0]) as stop:
        try:
            while solver.t < scene.t_end:
                if writer is not None and solver.t >= next_frame:
                    write_frame(writer, scene, solver)
                    next_frame += frame_interval
                remaining = scene.t_end - solver.t
                if scene.dt is None:
                    dt = solver.step(dt_max=remaining)
                else:  # a last step shorter than 1e-9 dt is merged into the one before
                    dt = solver.step(remaining if remaining <= scene.dt * (1 + 1e-9) else scene.dt)
                final = dt >= remaining
                if not final and remaining > MAX_STEPS * dt:  # e.g. velocities of 1e200: no progress
                    solver._fail(f"time step collapse: dt = {dt:.3g} would need more than {MAX_STEPS:.0e} steps to "
                                 f"reach t_end = {scene.t_end:g}")
                if final:  # the final step: end exactly at t_end
                    solver.t = scene.t_end
                row = {"step": solver.step_count, "dt": dt, **solver.energies()}
                history.append(row)
                if writer is not None:
                    writer.energies(row)
                monitor.after_step(dt, row, final=final)
                if scene.watch is not None:
                    scene.watch(solver)
                if callback is not None:
                    callback(solver)
                if (checkpoint_every is not None and solver.step_count % checkpoint_every == 0) or \
                        ((checkpoint_every is not None or resume) and solver.t >= scene.t_end):
                    save()  # every checkpoint_every steps, and at the end of a checkpointed or resumed run
                if out is not None and (signum := checkpoint.requested(stop, comm)):
                    raise checkpoint.RunInterrupted(signum, solver.t, save())
                if not bar.disable:
                    bar.set_postfix_str(f"step {solver.step_count}, dt = {dt:.3g}", refresh=False)
                    bar.update(solver.t - bar.n)
            monitor.outcome = "completed"
        except (SimulationError, SingularMassError) as e:  # collective: every rank raises the same
            monitor.outcome, monitor.error, failure = "aborted", str(e), e
        except checkpoint.RunInterrupted as e:  # collective too: the flag is reduced over ranks
            monitor.outcome, monitor.error, failure = "interrupted", str(e), e
        finally:
            failed = isinstance(failure, (SimulationError, SingularMassError))  # a state that may not be finite
            if writer is not None:
                try:  # the final state; of a failed run the particles' only
                    write_frame(writer, scene, solver, grid=not failed and solver.grid_velocity is not None,
                                particles=True)
                finally:
                    writer.close()
    wall = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    nglob = scene.particles.num_global
    summary = {
        "scene": scene.name,
        "params": scene.params,
        "particles": nglob,
        "steps": solver.step_count,
        "t_end": solver.t,
        "wall_time_s": wall,
        "particle_steps_per_s": nglob * (solver.step_count - steps0) / wall if wall > 0 else 0.0,
        "terms_assembled": dict(solver.terms),
        "final": history[-1],
        "initial": history[0],
        "status": monitor.outcome,
        "health": monitor.summary(),
    }
    if scene.results is not None and not failed:
        summary.update(scene.results(scene, solver))
    if progress and comm.rank == 0 and failure is None:
        print(f"{scene.name}: {solver.step_count} steps to t = {solver.t:.4g} in {wall:.2f} s "
              f"({summary['particle_steps_per_s']:.3g} particle-steps/s)")
    if writer is not None:
        writer.summary(summary)
    if failure is not None:  # the summary and the frames are written: now stop
        failure.health = {**summary["health"], "steps": solver.step_count}  # for studies that catalogue failures
        raise failure
    summary["history"] = history
    summary["solver"] = solver
    return summary
