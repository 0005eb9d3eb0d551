"""Which implementation the kernels use: numba when installed (unless ``FEMPM_KERNELS=numpy``),
else the numpy references."""

from __future__ import annotations

import os
from collections.abc import Callable

__all__ = ["pick"]

try:
    import numba  # noqa: F401

    COMPILED = os.environ.get("FEMPM_KERNELS", "numba") != "numpy"
except ImportError:
    COMPILED = False


def pick(compiled: Callable, reference: Callable) -> Callable:
    """The compiled kernel where :data:`COMPILED`, else its numpy reference."""
    return compiled if COMPILED else reference
