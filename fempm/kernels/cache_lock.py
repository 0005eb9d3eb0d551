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
kernel's callees) cannot deadlock. Without ``fcntl`` (Windows) the locks are not installed.

And it names every closure's compiled code apart (:func:`distinct_variant_ids`): numba names a
compiled function (its symbol and its environment of constant objects) by its qualified name,
its argument types and a counter of the process that compiled it. Two variants of one factory's
kernel compiled in two processes can take the same count; a third process that loads both from
the cache then finds one environment under both names (numba's ``_rebuild_env`` returns the one
it knows) and one symbol for both functions: in a test run of 2026-12-07 a kernel read another
variant's constants ("In 'NRT_adapt_ndarray_to_python', 'descr' is NULL"), and a variant can as
well call the other's helper without an error. The closure's contents now enter the count, and
a closure's code saved before (its id below :data:`TAGGED`) is compiled anew rather than loaded.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import tempfile

__all__ = ["distinct_variant_ids", "install", "lock_path", "variant_lock_path", "variant_tag"]

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


def variant_tag(func) -> int | None:
    """A number telling apart the functions defined in another function (a factory's kernels,
    ``<locals>`` in their qualified name): a digest of the qualified name and the pickled
    contents of the closure (none, or one that cannot be pickled: numba keeps no cache of it
    then); None for a function of a module."""
    if "<locals>" not in func.__qualname__:
        return None
    from numba.core.serialize import dumps

    try:
        data = dumps(tuple(c.cell_contents for c in func.__closure__)) if func.__closure__ else b""
    except Exception:  # noqa: BLE001 - any pickling failure
        data = b"?"
    return int.from_bytes(hashlib.sha256(func.__qualname__.encode() + data).digest()[:6], "big")


def distinct_variant_ids() -> bool:
    """Make the id numba gives each compilation of a factory's function (``FunctionIdentity.unique_id``,
    part of its symbol's and its environment's names) the process's count times 2^48 plus
    :func:`variant_tag`, so that variants compiled in different processes never share a name
    (see the module); returns whether it is in place. Idempotent."""
    try:
        from numba.core.bytecode import FunctionIdentity
    except ImportError:  # pragma: no cover - without numba there is nothing to name
        return False
    made = FunctionIdentity.from_function.__func__
    if getattr(made, "fempm_distinct", False):
        return True

    def from_function(cls, pyfunc):
        self = made(cls, pyfunc)
        tag = variant_tag(self.func)
        if tag is not None:
            self.unique_id = self.unique_id * TAGGED + tag
            self.unique_name = f"{self.func_qualname}${self.unique_id}"
        return self

    from_function.fempm_distinct = True
    FunctionIdentity.from_function = classmethod(from_function)
    _reload_tagged()
    return True


#: the ids :func:`distinct_variant_ids` gives closures are at least this (numba's own count less)
TAGGED = 2**48


def _reload_tagged() -> None:
    """Make numba's cache refuse a closure's code saved before :func:`distinct_variant_ids` (its
    id below :data:`TAGGED`: its names may be another variant's), so that it is compiled anew."""
    from numba.core.caching import Cache

    load = Cache.load_overload
    if getattr(load, "fempm_tagged", False):
        return

    def load_overload(self, sig, target_context):
        data = load(self, sig, target_context)
        fndesc = getattr(data, "fndesc", None)
        if fndesc is not None and "<locals>" in fndesc.qualname and (fndesc.uid or 0) < TAGGED:
            return None
        return data

    load_overload.fempm_tagged = True
    Cache.load_overload = load_overload


def install() -> bool:
    """Lock numba's cache saves (exclusive) and loads (shared) against other processes, and each
    variant's compilation (:func:`variant_lock_path`); returns whether the locks are in place
    (numba and ``fcntl`` present). Idempotent."""
    distinct_variant_ids()
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
