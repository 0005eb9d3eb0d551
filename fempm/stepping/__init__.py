"""The explicit MPM step: its options, the solver, the compiled lumped and consistent passes,
multi-field contact, loads and the run's health checks."""

from fempm.meshes.cell_sizes import cell_sizes
from fempm.stepping.laws import law_state, law_stress
from fempm.stepping.loads import Loads
from fempm.stepping.options import (
    MASS_RATIO_ITERATIONS,
    MASS_RATIO_SAFETY,
    Scheme,
    SimulationError,
    StepOptions,
)
from fempm.stepping.solver import ExplicitSolver

__all__ = [
    "ExplicitSolver",
    "Loads",
    "MASS_RATIO_ITERATIONS",
    "MASS_RATIO_SAFETY",
    "Scheme",
    "SimulationError",
    "StepOptions",
    "cell_sizes",
    "law_state",
    "law_stress",
]
