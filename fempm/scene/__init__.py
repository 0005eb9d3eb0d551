"""Scenes and the run loop: a scene is data; :func:`run` builds the solver for exactly what the
scene declares and writes its outputs as it goes."""

from fempm.scene.definition import (
    MAX_STEPS,
    OUTPUTS,
    VARIANTS,
    Scene,
    check_counts,
    check_finite,
    dofs_per_cell,
    emptiest_cell,
)
from fempm.scene.loop import RUN_STATS, outcome_of, run, run_stats, write_frame
from fempm.scene.recorder import Recorder

__all__ = [
    "MAX_STEPS",
    "OUTPUTS",
    "RUN_STATS",
    "Recorder",
    "Scene",
    "VARIANTS",
    "check_counts",
    "check_finite",
    "dofs_per_cell",
    "emptiest_cell",
    "outcome_of",
    "run",
    "run_stats",
    "write_frame",
]
