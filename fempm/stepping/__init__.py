"""The explicit MPM step: its options and schemes, the solver (the state's owner, the step as
the stages of the cycle), the grids that implement the stages (one field, a field per body with
contact, compiled passes), loads, the laws' calls, energies and the run's health checks."""

from fempm.meshes.cell_sizes import cell_sizes
from fempm.stepping.laws import law_state, law_stress
from fempm.stepping.loads import Loads
from fempm.stepping.options import SchemeName, SimulationError, StepOptions
from fempm.stepping.schemes import Scheme
from fempm.stepping.solver import ExplicitSolver, Solver, StepRecord
from fempm.transfer.mass_models import MASS_RATIO_ITERATIONS, MASS_RATIO_SAFETY

__all__ = [
    "MASS_RATIO_ITERATIONS",
    "MASS_RATIO_SAFETY",
    "ExplicitSolver",
    "Loads",
    "Scheme",
    "SchemeName",
    "SimulationError",
    "Solver",
    "StepOptions",
    "StepRecord",
    "cell_sizes",
    "law_state",
    "law_stress",
]
