"""Parameter matrices for the tests: every combination of the axes, the default run taking a
covering subset (every value of the first axis once, the other axes rotating so that every
value of each appears) and the rest marked ``slow`` (``make test`` passes them over;
``pytest -m slow`` and ``make test-all`` run them).

The compiled passes are specialised by cell, scheme and mass: each combination is a numba
compilation of its own on a clean clone, which is what the default run's time is spent on."""

from __future__ import annotations

import itertools

import pytest

__all__ = ["covering"]


def covering(*axes) -> list:
    """The combinations of ``axes`` as ``pytest.param`` tuples.

    A combination ``(a0[i0], a1[i1], ..., ak[ik])`` is in the default run when, for every
    axis ``j >= 1``, ``ij == (i0 + (j - 1) * (i0 // len(aj))) mod len(aj)``: one combination
    for each value of the first axis, the second rotating with it and each further axis
    rotating with a shift each time it wraps around, so that the pairs of two later axes
    vary too. Every value of every axis is in the default run when the first axis is the
    longest. The others are marked slow.
    """
    if len(axes) < 2:
        raise ValueError("covering needs at least two axes")
    params = []
    for index in itertools.product(*(range(len(a)) for a in axes)):
        values = tuple(a[i] for a, i in zip(axes, index))
        i0 = index[0]
        kept = all(index[j] == (i0 + (j - 1) * (i0 // len(axes[j]))) % len(axes[j]) for j in range(1, len(axes)))
        params.append(pytest.param(*values, marks=() if kept else pytest.mark.slow))
    return params
