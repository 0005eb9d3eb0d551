r"""Checkpoint and restart of a :func:`fempm.scene.run`.

A checkpoint is the folder ``OUT/checkpoint/``:

* ``rank_NNNNN.npz``, one per rank: the rank's particles with every array (``x``, ``cells``,
  ``X``, ``mass``, ``volume``, ``ids`` and each field as ``field:NAME``; numpy's own format,
  exact, readable with ``numpy.load``), and the solver's per-rank warm starts (the last grid
  velocity; with consistent mass the last grid acceleration);
* ``manifest.json``: the time, the step count, the number of ranks, the scene's name,
  parameters and options, how to rebuild the scene (the command line's scene and options),
  the solver's and the run-health monitor's accumulated state, and the writer's frame count.

It is written atomically: every rank writes into ``checkpoint.tmp/``, then rank 0 swaps it
in (``checkpoint`` -> ``checkpoint.old``, ``checkpoint.tmp`` -> ``checkpoint``, remove the
old one), so a run killed at any moment leaves a complete checkpoint (:func:`read` falls back
to ``checkpoint.old`` if it was killed inside the swap).

Restoring on the same number of ranks puts every array back as it was, in the same order, so
that the continued run is bit for bit the uninterrupted one. With consistent mass the compiled
step's kept systems go in too
(:meth:`fempm.consistent_step.ConsistentPointStep.checkpoint_arrays`: the sparsity's cells,
the matrix values each preconditioner was set up from, the warm starts and counters), and the
preconditioners are set up again from those values. On another number of ranks the particles
are distributed anew by their cells (:class:`fempm.particles.Particles`) and the warm starts
and kept systems are dropped: results agree to round-off.
"""

from __future__ import annotations

import json
import shutil
import signal
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from mpi4py import MPI

FORMAT = 1
FOLDER = "checkpoint"


class CheckpointError(RuntimeError):
    """A checkpoint that is missing, incomplete or does not fit the scene it is restored into."""


def _jsonable(v):
    """numpy values as plain numbers and lists; anything else by its repr."""
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    return repr(v)


def _scalar_state(obj, names) -> dict:
    out = {}
    for k in names:
        v = getattr(obj, k)
        out[k] = v.tolist() if isinstance(v, np.ndarray) else v
    return out


#: the HealthMonitor attributes that accumulate over a run
MONITOR_STATE = ("e0", "e_max", "momentum0", "work", "impulse", "_power", "_force", "first_dt", "_t_prev", "j_min",
                 "j_max", "p_scale", "drift", "ratio")


def write(out: Path, scene, solver, monitor, writer_state: dict, rebuild: dict | None = None) -> Path:
    """Write the run's state into ``out/checkpoint/`` (collective, atomic); returns its path."""
    comm = solver.particles.comm
    out = Path(out)
    tmp, final, old = out / (FOLDER + ".tmp"), out / FOLDER, out / (FOLDER + ".old")
    if comm.rank == 0:
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
    comm.Barrier()
    p = solver.particles
    arrays = {"x": p.x, "cells": p.cells, "X": p.X, **p._arrays()}
    if solver.grid_velocity is not None:
        arrays["solver:grid_velocity"] = solver.grid_velocity
    step = solver._lumped_step
    if hasattr(step, "checkpoint_arrays"):  # the consistent step's warm starts and kept systems
        arrays.update({f"solver:{k}": v for k, v in step.checkpoint_arrays().items()})
    error = None
    try:
        with open(tmp / f"rank_{comm.rank:05d}.npz", "wb") as fh:
            np.savez(fh, **arrays)
    except OSError as e:
        error = f"rank {comm.rank}: {e}"
    errors = [e for e in comm.allgather(error) if e]
    if errors:
        raise CheckpointError(f"writing the checkpoint in {tmp} failed: {'; '.join(errors)}")
    manifest = {
        "format": FORMAT, "ranks": comm.size, "t": solver.t, "step_count": solver.step_count,
        "t_end": scene.t_end, "scene": scene.name, "params": scene.params, "rebuild": rebuild,
        "options": {k: v if isinstance(v, (bool, int, float, str, type(None))) else repr(v)
                    for k, v in vars(scene.options).items()},
        "particles": p.num_global,
        "solver": {"extended_steps": solver.extended_steps, "mass_ratio": solver.mass_ratio,
                   "j_range": list(solver.j_range) if solver.j_range is not None else None,
                   "terms": dict(solver.terms), "since_sort": getattr(step, "_since_sort", None),
                   "ratio_age": getattr(step, "_ratio_age", None)},
        "monitor": _scalar_state(monitor, MONITOR_STATE),
        "writer": writer_state,
    }
    if comm.rank == 0:
        (tmp / "manifest.json").write_text(json.dumps(manifest, indent=1, default=_jsonable))
        if final.exists():
            shutil.rmtree(old, ignore_errors=True)
            final.rename(old)
        tmp.rename(final)
        shutil.rmtree(old, ignore_errors=True)
    comm.Barrier()
    return final


def folder(out: Path) -> Path:
    """The complete checkpoint in ``out`` (``checkpoint``, else ``checkpoint.old`` left by a run
    killed while swapping them); a :class:`CheckpointError` if there is none."""
    for name in (FOLDER, FOLDER + ".old"):
        path = Path(out) / name
        if (path / "manifest.json").is_file():
            return path
    raise CheckpointError(f"no checkpoint in {str(out)!r} (a run writes one with checkpoint_every / "
                          "--checkpoint-every, and when it is interrupted)")


def manifest(out: Path) -> dict:
    """The manifest of the checkpoint in ``out``."""
    data = json.loads((folder(out) / "manifest.json").read_text())
    if data.get("format") != FORMAT:
        raise CheckpointError(f"checkpoint format {data.get('format')} is not {FORMAT}")
    return data


def _load(path: Path) -> dict:
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def restore_particles(out: Path, scene, comm: MPI.Comm) -> tuple[dict, dict]:
    """Put the checkpoint's particles into ``scene`` (before its solver is built); returns
    (manifest, this rank's solver arrays: warm starts, empty on another number of ranks)."""
    from fempm.particles import Particles

    data = manifest(out)
    path = folder(out)
    if data["scene"] != scene.name:
        raise CheckpointError(f"the checkpoint in {str(out)!r} is of scene {data['scene']!r}, not {scene.name!r}")
    if comm.size == data["ranks"]:  # the same layout: every array back in place and order
        arrays = _load(path / f"rank_{comm.rank:05d}.npz")
        solver_arrays = {k[7:]: arrays.pop(k) for k in list(arrays) if k.startswith("solver:")}
        scene.particles._set_arrays(arrays)
    else:  # read a share of the files, then let each particle go to the rank owning its cell
        parts = [_load(path / f"rank_{r:05d}.npz") for r in range(comm.rank, data["ranks"], comm.size)]
        if not parts:  # more ranks than files: none here, of the right shapes and types
            parts = [{k: v[:0] for k, v in _load(path / "rank_00000.npz").items()}]
        merged = {k: np.concatenate([q[k] for q in parts]) for k in parts[0] if not k.startswith("solver:")}
        d = scene.mesh.geometry.dim
        fields = {k[6:]: v for k, v in merged.items() if k.startswith("field:")}
        scene.particles = Particles(scene.mesh, merged["x"].reshape(-1, d), merged["mass"], merged["volume"],
                                    fields=fields, ids=merged["ids"], locator=scene.particles.locator)
        solver_arrays = {}
    if scene.particles.num_global != data["particles"]:
        raise CheckpointError(f"restored {scene.particles.num_global} particles, the checkpoint holds {data['particles']}")
    return data, solver_arrays


def restore_solver(solver, monitor, data: dict, solver_arrays: dict) -> None:
    """Put the checkpoint's solver and run-health state into a solver built on the restored
    particles (and its monitor)."""
    from collections import Counter

    s = data["solver"]
    solver.t, solver.step_count = float(data["t"]), int(data["step_count"])
    solver.extended_steps, solver.mass_ratio = int(s["extended_steps"]), float(s["mass_ratio"])
    solver.j_range = tuple(s["j_range"]) if s["j_range"] is not None else None
    solver.terms = Counter(s["terms"])
    solver.grid_velocity = solver_arrays.get("grid_velocity")
    step = solver._compiled_step() if solver.compiled is not False else None
    if step is not None:
        if s["since_sort"] is not None:
            step._since_sort = int(s["since_sort"])
        if hasattr(step, "restore_arrays"):
            if s["ratio_age"] is not None:
                step._ratio_age = int(s["ratio_age"])
            # collective: on another number of ranks every rank passes {} (no solver arrays)
            step.restore_arrays(solver_arrays)
    for k, v in data["monitor"].items():
        setattr(monitor, k, np.asarray(v) if isinstance(v, list) else v)


class RunInterrupted(Exception):
    """A run stopped by SIGTERM or SIGINT at a step boundary, after writing its checkpoint."""

    def __init__(self, signum: int, t: float, path: Path | None):
        self.signum = signum
        where = f"; checkpoint in {path}" if path is not None else ""
        super().__init__(f"interrupted by {signal.Signals(signum).name} at t = {t:.6g}{where}")


@contextmanager
def stop_requests(comm: MPI.Comm):
    """While active, SIGTERM and SIGINT only set a flag (returned as a one-item list, with the
    signal number); :func:`requested` tells every rank at the step boundary. Outside the main
    thread nothing is installed."""
    flag = [0]

    def handler(signum, frame):
        flag[0] = signum

    installed = {}
    try:
        for sig in (signal.SIGTERM, signal.SIGINT):
            installed[sig] = signal.signal(sig, handler)
    except ValueError:  # not the main thread
        pass
    try:
        yield flag
    finally:
        for sig, previous in installed.items():
            signal.signal(sig, previous)


def requested(flag: list, comm: MPI.Comm) -> int:
    """The signal any rank received (0: none); collective."""
    return flag[0] if comm.size == 1 else comm.allreduce(flag[0], op=MPI.MAX)
