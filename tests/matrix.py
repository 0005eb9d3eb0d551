"""Parameter matrices for the tests: every combination of the axes, the default run taking a
covering subset (every value of every axis, every pair of the first two with a rotating last
one) and the rest marked ``slow`` (``make test`` passes them over; ``pytest -m slow`` runs them).

The compiled passes are specialised by cell, scheme and mass: each combination is a numba
compilation of its own on a clean clone, which is what the default run's time is spent on."""

from __future__ import annotations

import itertools

import pytest

__all__ = ["covering"]


def covering(*axes) -> list:
    """The combinations of ``axes`` as ``pytest.param`` tuples.

    A combination ``(a0[i0], ..., ak[ik])`` is in the default run when
    ``ik == (i0 + ... + i(k-1)) mod len(ak)``: with two axes every value of the first with
    the second rotating, with three every pair of the first two (a Latin square: every pair
    of any two axes when the last is no longer than the others). The others are marked slow.
    """
    if len(axes) < 2:
        raise ValueError("covering needs at least two axes")
    params = []
    for index in itertools.product(*(range(len(a)) for a in axes)):
        values = tuple(a[i] for a, i in zip(axes, index))
        kept = index[-1] == sum(index[:-1]) % len(axes[-1])
        params.append(pytest.param(*values, marks=() if kept else pytest.mark.slow))
    return params
