"""Periods measured from a scene's history: the crossings of zero by a sampled signal."""

from __future__ import annotations

import numpy as np

__all__ = ["crossing_period"]


def crossing_period(t: np.ndarray, x: np.ndarray) -> float:
    """Twice the mean time between the crossings of 0 by ``x(t)`` (linear between samples);
    NaN with fewer than two crossings."""
    t, x = np.asarray(t, dtype=float), np.asarray(x, dtype=float)
    i = np.flatnonzero(np.signbit(x[:-1]) != np.signbit(x[1:]))
    if len(i) < 2:
        return float("nan")
    tc = t[i] - x[i] * (t[i + 1] - t[i]) / (x[i + 1] - x[i])
    return float(2.0 * np.mean(np.diff(tc)))
