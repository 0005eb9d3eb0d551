"""Which implementation the kernels use: numba when installed (unless ``FEMPM_KERNELS=numpy``),
else the numpy references; and how numba compiles them.

:data:`INLINE` is the ``inline`` option of the kernels' small helpers (``njit(inline=INLINE)``):
``"always"`` (the default) inlines them into each pass at numba's IR level, which the passes'
speed depends on (APIC's triangle pass takes 1.7 times as long with the helpers called);
``FEMPM_NUMBA_INLINE=never`` leaves them as calls, the same arithmetic in about a third of the
compile time (numba copies a helper's IR at every site it inlines it). The test run takes
``never`` (``scripts/run-tests``); its kernels then go to a cache folder of their own
(``inline-never`` in numba's cache folder, or in ``fempm/kernels/__pycache__``, or in the
temporary directory), so that a later run of the shipped kernels never loads them.
"""

from __future__ import annotations

import os
from collections.abc import Callable

__all__ = ["COMPILED", "INLINE", "pick"]

#: ``FEMPM_NUMBA_INLINE``'s values
INLINE_OPTIONS = ("always", "never")
INLINE = os.environ.get("FEMPM_NUMBA_INLINE", "always")
if INLINE not in INLINE_OPTIONS:
    raise ValueError(f"FEMPM_NUMBA_INLINE={INLINE!r}: expected one of {', '.join(INLINE_OPTIONS)}")

try:
    import numba  # noqa: F401

    COMPILED = os.environ.get("FEMPM_KERNELS", "numba") != "numpy"
except ImportError:
    COMPILED = False


def _cache_folder(mode: str) -> str:
    """The cache folder of the kernels compiled with ``inline=mode``: ``inline-<mode>`` in
    numba's cache folder (``NUMBA_CACHE_DIR``), else in this package's ``__pycache__``, else
    (a package folder one cannot write to) in the temporary directory."""
    import tempfile

    import numba.core.config

    if numba.core.config.CACHE_DIR:
        return os.path.join(numba.core.config.CACHE_DIR, f"inline-{mode}")
    here = os.path.dirname(os.path.abspath(__file__))
    if os.access(here, os.W_OK):
        return os.path.join(here, "__pycache__", f"inline-{mode}")
    uid = os.getuid() if hasattr(os, "getuid") else 0
    return os.path.join(tempfile.gettempdir(), f"fempm-numba-{uid}", f"inline-{mode}")


if COMPILED and INLINE != "always":
    numba.core.config.CACHE_DIR = _cache_folder(INLINE)


def pick(compiled: Callable, reference: Callable) -> Callable:
    """The compiled kernel where :data:`COMPILED`, else its numpy reference."""
    return compiled if COMPILED else reference
