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
load takes milliseconds; compilation, the slow part, stays outside that lock.

It also makes every variant compile once over all the processes that share the cache: a
dispatcher compiling a signature first takes an exclusive lock of its own for that variant
(one lock file per cache index key: the function, its signature, the machine and the hash of
its closure, in a folder per user in the temporary directory), then looks in the cache. A
second process that needs the same variant meanwhile (the other test worker, the other MPI
rank) waits for the first and loads its result instead of compiling it again; different
variants still compile side by side. A call graph has no cycles, so nested compilations (a
kernel's callees) cannot deadlock. Without ``fcntl`` (Windows) nothing is installed.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import tempfile

__all__ = ["install", "lock_path", "variant_lock_path"]

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None


def lock_path() -> str:
    """The lock file of this user's numba cache writes."""
    uid = os.getuid() if hasattr(os, "getuid") else 0
    return os.path.join(tempfile.gettempdir(), f"fempm-numba-cache-{uid}.lock")


def variant_lock_path(key: str) -> str:
    """The lock file of one compiled variant (``key``: a digest of its cache index key)."""
    uid = os.getuid() if hasattr(os, "getuid") else 0
    return os.path.join(tempfile.gettempdir(), f"fempm-numba-compile-{uid}", f"{key}.lock")


@contextlib.contextmanager
def _locked(mode: int, path: str | None = None):
    """Hold ``fcntl.flock(mode)`` on ``path`` (default :func:`lock_path`; nothing if it cannot
    be opened)."""
    try:
        path = lock_path() if path is None else path
        os.makedirs(os.path.dirname(path), mode=0o700, exist_ok=True)
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
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


def _variant_key(dispatcher, sig) -> str | None:
    """A digest of what names ``dispatcher``'s compiled variant for ``sig`` in its disk cache
    (numba's index key: the function's code, the pickled contents of its closure, the signature
    and the machine); None where its closure cannot be pickled (numba then keeps no cache of
    it either). A dispatcher without a disk cache gets a key too: two processes compiling it at
    once take turns, each compiling it (milliseconds to wait for in practice: fempm's kernels
    are cached, and numba compiles its inlined helpers into them)."""
    from numba.core.serialize import dumps

    f = dispatcher.py_func
    try:
        closure = dumps(tuple(c.cell_contents for c in f.__closure__)) if f.__closure__ else b""
    except Exception:  # noqa: BLE001 - any pickling failure
        return None
    key = (f.__module__, f.__qualname__, f.__code__.co_filename, f.__code__.co_firstlineno, str(sig),
           dispatcher.targetctx.codegen().magic_tuple(), hashlib.sha256(f.__code__.co_code).hexdigest(),
           hashlib.sha256(closure).hexdigest())
    return hashlib.sha256(repr(key).encode()).hexdigest()[:32]


#: the variant locks this process holds
_HELD: set[str] = set()


def _compile_once(compile_):
    @functools.wraps(compile_)
    def compile_locked(self, sig):
        key = _variant_key(self, sig)
        if key is None or key in _HELD:  # (a recursive compilation holds its own lock already)
            return compile_(self, sig)
        from numba.core.compiler_lock import global_compiler_lock  # (re-entrant; numba's compile takes it too)

        with global_compiler_lock, _locked(fcntl.LOCK_EX, variant_lock_path(key)):  # another process may be compiling it
            _HELD.add(key)
            try:
                return compile_(self, sig)  # loads it from the cache if that process saved it
            finally:
                _HELD.discard(key)

    compile_locked.fempm_locked = True
    return compile_locked


def install() -> bool:
    """Lock numba's cache saves (exclusive) and loads (shared) against other processes, and each
    variant's compilation (:func:`variant_lock_path`); returns whether the locks are in place
    (numba and ``fcntl`` present). Idempotent."""
    if fcntl is None:  # pragma: no cover - Windows
        return False
    try:
        from numba.core.caching import IndexDataCacheFile
        from numba.core.dispatcher import Dispatcher
    except ImportError:  # pragma: no cover - without numba there is no cache
        return False
    if not getattr(IndexDataCacheFile.save, "fempm_locked", False):
        IndexDataCacheFile.save = _wrap(IndexDataCacheFile.save, fcntl.LOCK_EX)
        IndexDataCacheFile.load = _wrap(IndexDataCacheFile.load, fcntl.LOCK_SH)
    if not getattr(Dispatcher.compile, "fempm_locked", False):
        Dispatcher.compile = _compile_once(Dispatcher.compile)
    return True
