"""Where a run's time goes: the wall time of its phases on each rank.

A run's summary (:func:`fempm.scene.run`, ``summary.json``) holds ``timings``, the seconds of

- ``mesh_s``: building the background mesh (gmsh, or reading it from the mesh cache,
  :mod:`fempm.meshes.cache`; a structured mesh; uniform refinement),
- ``particles_s``: seeding the particles and locating them in their cells,
- ``solver_s``: building the solver (spaces, conditions, the transfer's pattern),
- ``first_step_s``: the first step (loading or compiling the kernels),
- ``steps_s``: the other steps,
- ``output_s``: the frames, the energies file and the final frame,
- ``checkpoint_s``: writing checkpoints,

each the slowest rank's. The set-up phases (mesh, particles) happen before the run, when the
scene is built: :data:`SETUP` gathers them as they happen and a :class:`fempm.scene.Scene`
takes what was gathered since the previous scene (:meth:`Timings.take`).
"""

from __future__ import annotations

import contextlib
import functools
import time
from collections.abc import Iterator

import numpy as np
from mpi4py import MPI

__all__ = ["PHASES", "SETUP", "Timings", "line", "phase", "timed"]

#: the phases of a run's ``timings``, in the order they happen
PHASES = ("mesh_s", "particles_s", "solver_s", "first_step_s", "steps_s", "output_s", "checkpoint_s")


class Timings:
    """Seconds per phase on this rank; a phase entered again inside itself (a seeding that
    constructs particles) counts once."""

    def __init__(self) -> None:
        self.seconds = dict.fromkeys(PHASES, 0.0)
        self._open: set[str] = set()

    @contextlib.contextmanager
    def phase(self, name: str) -> Iterator[None]:
        """Add the time spent in the ``with`` block to phase ``name`` (one of :data:`PHASES`)."""
        if name not in self.seconds:
            raise ValueError(f"unknown phase {name!r}; expected one of {PHASES}")
        if name in self._open:
            yield
            return
        self._open.add(name)
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[name] += time.perf_counter() - t0
            self._open.discard(name)

    def add(self, other: dict[str, float]) -> None:
        """Add the seconds of ``other`` (a :meth:`take`)."""
        for k, v in other.items():
            self.seconds[k] += v

    def take(self) -> dict[str, float]:
        """The phases gathered so far (the non-zero ones), and start again from zero."""
        taken = {k: v for k, v in self.seconds.items() if v}
        self.seconds = dict.fromkeys(PHASES, 0.0)
        return taken

    def slowest(self, comm: MPI.Comm) -> dict[str, float]:
        """Every phase's seconds on the slowest rank for it (collective)."""
        local = np.array([self.seconds[k] for k in PHASES])
        slowest = np.empty_like(local)
        comm.Allreduce(local, slowest, op=MPI.MAX)
        return dict(zip(PHASES, slowest.tolist()))


def line(timings: dict[str, float]) -> str:
    """A run's ``timings`` as one line of text (``mesh 1.2 s, particles 0.3 s, ...``)."""
    return ", ".join(f"{k[:-2].replace('_', ' ')} {v:.3g} s" for k, v in timings.items())


#: the set-up phases (mesh, particles) gathered for the next scene
SETUP = Timings()


def phase(name: str):
    """``with phase("mesh_s"):`` adds the block's time to the set-up phase ``name`` (:data:`SETUP`)."""
    return SETUP.phase(name)


def timed(name: str):
    """A decorator: every call of the function counts to the set-up phase ``name``."""

    def wrap(fn):
        @functools.wraps(fn)
        def call(*args, **kwargs):
            with SETUP.phase(name):
                return fn(*args, **kwargs)

        return call

    return wrap
