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
"""

from __future__ import annotations

import contextlib
import sys
import time
import traceback

#: seconds between the failing rank's message and MPI_Abort
GRACE = 1.0


@contextlib.contextmanager
def abort_on_error(comm=None):
    """On more than one rank of ``comm`` (default ``MPI.COMM_WORLD``), an exception (or
    KeyboardInterrupt) leaving the block prints its traceback with the rank and aborts all
    ranks with exit code 1; on one rank it propagates. ``SystemExit`` passes through."""
    try:
        yield
    except (Exception, KeyboardInterrupt):
        from mpi4py import MPI

        comm = comm or MPI.COMM_WORLD
        if comm.size == 1:
            raise
        sys.stderr.write(f"fempm: rank {comm.rank} of {comm.size} failed; aborting all ranks\n{traceback.format_exc()}")
        sys.stderr.flush()
        time.sleep(GRACE)  # mpiexec forwards the message before MPI_Abort ends the job (else it may be lost)
        comm.Abort(1)
