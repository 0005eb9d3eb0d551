"""Stopping a run cleanly on a signal: SIGTERM (a batch system's time limit) and SIGINT
(Ctrl-C) only set a flag while a run is going; at the next step boundary every rank learns of
it (:func:`requested`), the run writes its checkpoint and ends with :class:`RunInterrupted`
(:class:`fempm.scene.observers.Checkpoints`)."""

from __future__ import annotations

import signal
from contextlib import contextmanager
from pathlib import Path

from mpi4py import MPI

__all__ = ["RunInterrupted", "requested", "stop_requests"]


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
