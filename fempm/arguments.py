"""Checks of the arguments of fempm's option objects (laws, step options): a value of the
wrong type names the argument, instead of failing later in a comparison or inside numpy."""

from __future__ import annotations

import dataclasses
import numbers

__all__ = ["check_numbers"]


def check_numbers(obj) -> None:
    """Every field of the dataclass ``obj`` annotated as a number (``float``, ``int``, possibly
    ``| None``) holds a real number (or None where allowed; booleans are not numbers here); else
    a TypeError naming the class, the field and the value."""
    for f in dataclasses.fields(obj):
        kinds = {k.strip() for k in str(f.type).split("|")}
        if not kinds & {"float", "int"}:
            continue
        value = getattr(obj, f.name)
        if value is None and "None" in kinds:
            continue
        integer = "float" not in kinds
        expected = numbers.Integral if integer else numbers.Real
        if isinstance(value, bool) or not isinstance(value, expected):
            raise TypeError(f"{type(obj).__name__}: {f.name}={value!r} must be {'an integer' if integer else 'a number'}"
                            + (" or None" if "None" in kinds else ""))
