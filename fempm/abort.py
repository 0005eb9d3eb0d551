"""Ending every rank when one fails.

Under ``mpiexec`` an exception raised on one rank leaves the others waiting in their next
collective call for ever. :func:`abort_on_error` turns an exception that leaves its block on
any rank into a message naming the rank, with the traceback, and ``MPI_Abort``: every rank
ends, with a non-zero exit. The command line runs inside it; scripts run under ``mpiexec``
can do the same::

    from fempm.abort import abort_on_error

    with abort_on_error():
        run(scene, "output/run")

Errors that every rank raises alike (fempm's checks of arguments and of the state are
collective) end the ranks the same way, only with ``MPI_Abort`` instead of a return.

:class:`FailureAgreement` tells a rank that caught an exception whether every rank caught one
(the failure is collective: the ranks can still write their outputs together) or only some
(the others wait in a collective call: only :func:`abort` ends them);
:func:`fempm.scene.run` uses it, so that a run under MPI never hangs whatever fails.
"""

from __future__ import annotations

import contextlib
import sys
import time
import traceback
from typing import TYPE_CHECKING, NoReturn

if TYPE_CHECKING:  # mpi4py is imported where it is used: the command line imports this module first
    from mpi4py import MPI

__all__ = ["AGREE_TIMEOUT", "GRACE", "FailureAgreement", "RankError", "abort", "abort_on_error", "raise_together"]

#: seconds between the failing rank's message and MPI_Abort
GRACE = 1.0
#: seconds the ranks that caught an exception wait for the others to catch one as well
AGREE_TIMEOUT = 2.0


def abort(comm: MPI.Comm, message: str) -> NoReturn:
    """Print ``message`` (with the current exception's traceback, if any) to stderr with this
    rank, then end every rank of ``comm`` with exit code 1 (``MPI_Abort``). Local: one rank
    may call it while the others wait anywhere."""
    trace = traceback.format_exc() if sys.exc_info()[0] is not None else ""
    sys.stderr.write(f"fempm: rank {comm.rank} of {comm.size} failed; aborting all ranks\n{message}\n{trace}")
    sys.stderr.flush()
    time.sleep(GRACE)  # mpiexec forwards the message before MPI_Abort ends the job (else it may be lost)
    comm.Abort(1)
    raise SystemExit(1)  # not reached: Abort does not return


class RankError(RuntimeError):
    """What the other ranks raise when one rank's part of a collective step failed
    (:func:`raise_together`): the failing rank and its error."""


def raise_together(comm: MPI.Comm, error: BaseException | None) -> None:
    """Raise on every rank of ``comm`` when ``error`` is set on any: the rank that caught it
    raises it, the others a :class:`RankError` naming that rank and the error. Collective:
    one reduction, and on a failure one gather of the messages. Call it after code that may
    raise on some ranks only (a user's law, a check of a rank's own arguments), where every
    rank reaches it."""
    if comm.size == 1:
        if error is not None:
            raise error
        return
    from mpi4py import MPI

    if not comm.allreduce(error is not None, op=MPI.LOR):
        return
    messages = comm.allgather(None if error is None else f"{type(error).__name__}: {error}")
    if error is not None:
        raise error
    rank, message = next((r, m) for r, m in enumerate(messages) if m is not None)
    raise RankError(f"rank {rank} of {comm.size} failed: {message}")


@contextlib.contextmanager
def abort_on_error(comm=None):
    """A context in which a failure on one rank ends every rank.

    On more than one rank of ``comm``, an exception (or KeyboardInterrupt) leaving the block
    prints its traceback with the rank and aborts all ranks with exit code 1
    (``MPI_Abort``); on one rank it propagates. ``SystemExit`` passes through.

    Args:
        comm: The communicator whose ranks end together (None: ``MPI.COMM_WORLD``).

    Example:
        ``with fempm.abort_on_error(): run(scene, out)``
    """
    try:
        yield
    except (Exception, KeyboardInterrupt) as e:
        from mpi4py import MPI

        comm = comm or MPI.COMM_WORLD
        if comm.size == 1:
            raise
        abort(comm, f"{type(e).__name__}: {e}")


class FailureAgreement:
    """Whether a failure on this rank is every rank's.

    Made collectively (it duplicates ``comm``, so that its barrier can never match a
    collective call of the computation); then a rank that caught an exception calls
    :meth:`everyone`: a non-blocking barrier that completes only if every rank calls it
    within ``timeout`` seconds, as ranks that raise alike do. A rank whose failure is its own
    finds the others absent (they wait in a collective call of ``comm``) and should
    :func:`abort`. Ranks must call :meth:`everyone` the same number of times."""

    def __init__(self, comm: MPI.Comm):
        self.comm = comm.Dup() if comm.size > 1 else None

    def everyone(self, timeout: float = AGREE_TIMEOUT) -> bool:
        """True when every rank reaches this call within ``timeout`` (at once on one rank)."""
        if self.comm is None:
            return True
        request = self.comm.Ibarrier()
        deadline = time.monotonic() + timeout
        while not request.Test():
            if time.monotonic() > deadline:
                return False
            time.sleep(1e-3)
        return True

    def free(self) -> None:
        """Release the duplicated communicator (collective; skip it after a one-rank failure)."""
        if self.comm is not None:
            self.comm.Free()
            self.comm = None
