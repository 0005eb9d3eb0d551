"""The interface of a manufactured problem with an exact solution."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

__all__ = ["Problem", "as_columns"]


def as_columns(X: npt.ArrayLike, dim: int) -> npt.NDArray:
    X = np.asarray(X, dtype=np.float64)
    X = X.reshape(-1, dim) if X.ndim < 2 else X
    if X.shape[1] != dim:
        raise ValueError(f"reference positions must have shape (n, {dim}), got {X.shape}")
    return X


@dataclass(frozen=True)
class Problem:
    """What every problem provides (see the module docstring).

    ``lower``/``upper``: the reference body's bounding box (the body itself for box problems);
    ``start_displaced``: particles start at :math:`X + u(X, 0)` with the deformation
    :math:`F(X, 0)` (else at :math:`X` with :math:`F = I`); ``has_body_force``: whether the
    body force is non-zero (a scene assembles the term only then).
    """

    name: str = field(init=False, default="")
    dim: int = field(init=False, default=1)
    has_body_force: bool = field(init=False, default=True)
    start_displaced: bool = field(init=False, default=False)

    def declare(self, **attributes) -> None:
        """Set the attributes a problem derives from its parameters (``name``, ``dim``,
        ``has_body_force``, ``start_displaced``; from ``__post_init__``, the dataclass being frozen)."""
        for key, value in attributes.items():
            object.__setattr__(self, key, value)

    @property
    def lower(self) -> tuple[float, ...]:
        return (0.0,) * self.dim

    @property
    def upper(self) -> tuple[float, ...]:
        return (1.0,) * self.dim

    def contains(self, X: npt.NDArray) -> npt.NDArray[np.bool_]:
        """Whether reference points (n, d) belong to the body."""
        X = as_columns(X, self.dim)
        return np.all((X >= np.array(self.lower)) & (X <= np.array(self.upper)), axis=1)

    def background(self, h: float) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """Lower and upper corners of the background mesh box for cells of size ``h``."""
        return self.lower, self.upper

    def walls(self) -> list[tuple[int, float, str]]:
        """Grid velocity conditions as ``(axis, coordinate, kind)``, kind ``fixed`` (all
        components zero) or ``slip`` (zero component along the axis)."""
        return []
