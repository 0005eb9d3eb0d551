"""Manufactured problems (:mod:`fempm.verification.manufactured`); this path stays for the code that imports it."""

from fempm.verification.manufactured import (
    PROBLEMS,
    AxisAligned,
    AxisAligned1D,
    GeneralizedVortex,
    Problem,
    VibratingBar,
    axis_aligned,
    axis_aligned_1d,
    generalized_vortex,
    vibrating_bar,
)

__all__ = [
    "PROBLEMS",
    "AxisAligned",
    "AxisAligned1D",
    "GeneralizedVortex",
    "Problem",
    "VibratingBar",
    "axis_aligned",
    "axis_aligned_1d",
    "generalized_vortex",
    "vibrating_bar",
]
