"""A file lock around numba's on-disk cache, for processes that compile at the same time.

numba saves a compiled kernel by reading the function's cache index, taking the first data
file number the index does not use, writing the index and then the data file. Two processes
that compile two variants of one function (the kernels of :mod:`fempm.kernels` are made by
factories, so all variants of a pass share one index) at the same time can both take the same
number: the index then names, for one variant, the data file of the other, and every later
process loads the wrong kernel without an error (numba issue 10128 discusses the same race for
gufuncs; numba has no lock). Test workers (pytest-xdist), MPI ranks and the parallel studies
all compile into one cache.

:func:`install` wraps numba's cache save in an exclusive and its load in a shared
``fcntl.flock`` on one lock file per user in the temporary directory, so that choosing a data
file, writing the index and writing the data are one step for every other process. A save or
load takes milliseconds; compilation, the slow part, stays outside the lock. Without ``fcntl``
(Windows) nothing is installed.
"""

from __future__ import annotations

import contextlib
import functools
import os
import tempfile

__all__ = ["install", "lock_path"]

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None


def lock_path() -> str:
    """The lock file of this user's numba cache writes."""
    uid = os.getuid() if hasattr(os, "getuid") else 0
    return os.path.join(tempfile.gettempdir(), f"fempm-numba-cache-{uid}.lock")


@contextlib.contextmanager
def _locked(mode: int):
    """Hold ``fcntl.flock(mode)`` on :func:`lock_path` (nothing if it cannot be opened)."""
    try:
        fd = os.open(lock_path(), os.O_RDWR | os.O_CREAT, 0o600)
    except OSError:  # pragma: no cover - e.g. a read-only temporary directory
        yield
        return
    try:
        fcntl.flock(fd, mode)
        yield
    finally:
        os.close(fd)  # releases the lock


def _wrap(method, mode: int):
    @functools.wraps(method)
    def locked(*args, **kwargs):
        with _locked(mode):
            return method(*args, **kwargs)

    locked.fempm_locked = True
    return locked


def install() -> bool:
    """Lock numba's cache saves (exclusive) and loads (shared) against other processes; returns
    whether the lock is in place (numba and ``fcntl`` present). Idempotent."""
    if fcntl is None:  # pragma: no cover - Windows
        return False
    try:
        from numba.core.caching import IndexDataCacheFile
    except ImportError:  # pragma: no cover - without numba there is no cache
        return False
    if not getattr(IndexDataCacheFile.save, "fempm_locked", False):
        IndexDataCacheFile.save = _wrap(IndexDataCacheFile.save, fcntl.LOCK_EX)
        IndexDataCacheFile.load = _wrap(IndexDataCacheFile.load, fcntl.LOCK_SH)
    return True
