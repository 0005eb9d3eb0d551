"""A scene is data (mesh, particles with a body index, materials, boundary conditions, loads,
transfer options, outputs); :func:`run` builds the explicit solver for exactly what the scene
declares and writes its outputs as it goes."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import dolfinx.fem
import dolfinx.mesh
import numpy as np
from mpi4py import MPI

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
    growth beyond the work of the loads, J bounds, time-step floor).
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

    def __post_init__(self):
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
        return ExplicitSolver(V, self.particles, self.materials, bcs=bcs, loads=self.loads, options=self.options)


#: the run summary's cost figures that demos report with their own results
RUN_STATS = ("steps", "particles", "particle_steps_per_s", "terms_assembled")


def run_stats(summary: dict) -> dict:
    """The :data:`RUN_STATS` entries of a :func:`run` summary."""
    return {k: summary[k] for k in RUN_STATS}


def run(
    scene: Scene,
    out: Path | None = None,
    *,
    progress: bool = True,
    png: bool = False,
    callback: Callable[[ExplicitSolver], None] | None = None,
) -> dict:
    """Run ``scene`` to ``t_end``. Energies and momentum are recorded every step (returned in
    ``history`` and, with ``out``, written to ``energies.csv`` as the run goes, together with
    particle VTK frames, the grid velocity and stress (VTX, the stress projected as a per-volume
    field, :meth:`ExplicitSolver.grid_stress`), ``summary.json`` and, with ``png``, a PNG of
    the particles per frame in ``frames/``). The scene's :class:`~fempm.health.Health` limits are
    checked every step; a run that crosses one (or fails otherwise: J <= 0, non-finite state,
    singular mass) still writes its summary (``status`` "aborted", ``health.error``) and a
    particle frame of the failing state, then raises the error."""
    solver = scene.solver()
    comm = scene.mesh.comm
    writer = RunWriter(Path(out), scene.particles, solver.V, png=png) if out is not None else None
    history = [solver.energies()]
    monitor = HealthMonitor(solver, scene.health)
    next_frame = 0.0
    t0 = time.perf_counter()
    last_print = t0
    failure: Exception | None = None
    try:
        while solver.t < scene.t_end:
            if writer is not None and solver.t >= next_frame:
                writer.particles(scene.particles, solver.t)
                if solver.grid_velocity is not None:
                    writer.grid(solver.grid_velocity, solver.t, stress=solver.grid_stress())
                next_frame += scene.t_end / max(scene.frames, 1)
            remaining = scene.t_end - solver.t
            if scene.dt is None:
                dt = solver.step(dt_max=remaining)
            else:  # a last step shorter than 1e-9 dt is merged into the one before
                dt = solver.step(remaining if remaining <= scene.dt * (1 + 1e-9) else scene.dt)
            final = dt >= remaining
            if final:  # the final step: end exactly at t_end
                solver.t = scene.t_end
            row = {"step": solver.step_count, "dt": dt, **solver.energies()}
            history.append(row)
            if writer is not None:
                writer.energies(row)
            monitor.after_step(dt, row, final=final)
            if callback is not None:
                callback(solver)
            now = time.perf_counter()
            if progress and comm.rank == 0 and now - last_print > 2.0:
                frac = solver.t / scene.t_end
                print(f"\r[{'#' * int(30 * frac):30s}] t = {solver.t:.4g} / {scene.t_end:g}  step {solver.step_count}  dt = {dt:.3g}",
                      end="", flush=True)
                last_print = now
        monitor.outcome = "completed"
    except (SimulationError, SingularMassError) as e:  # collective: every rank raises the same
        monitor.outcome, monitor.error, failure = "aborted", str(e), e
    finally:
        if writer is not None:
            try:
                writer.particles(scene.particles, solver.t)  # the final (or failing) state
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
        "particle_steps_per_s": nglob * solver.step_count / wall if wall > 0 else 0.0,
        "terms_assembled": dict(solver.terms),
        "final": history[-1],
        "initial": history[0],
        "status": monitor.outcome,
        "health": monitor.summary(),
    }
    if progress and comm.rank == 0 and failure is None:
        print(f"\r{scene.name}: {solver.step_count} steps to t = {solver.t:.4g} in {wall:.2f} s "
              f"({summary['particle_steps_per_s']:.3g} particle-steps/s)" + " " * 20)
    if writer is not None:
        writer.summary(summary)
    if failure is not None:  # the summary and the frames are written: now stop
        failure.health = {**summary["health"], "steps": solver.step_count}  # for studies that catalogue failures
        raise failure
    summary["history"] = history
    summary["solver"] = solver
    return summary
