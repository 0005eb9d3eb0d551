"""fempm: the Material Point Method on DOLFINx background meshes.

The particle-to-grid map is the mass-weighted least-squares (Galerkin) projection of the
particle data onto a DOLFINx finite element space, with the consistent mass matrix
(PETSc Mat + KSP) or its lumped (row-sum) approximation.

The packages follow the MPM cycle, lowest layer first: :mod:`fempm.kernels` (compiled passes),
:mod:`fempm.meshes`, :mod:`fempm.materials`, :mod:`fempm.particles`, :mod:`fempm.transfer`,
:mod:`fempm.boundary`, :mod:`fempm.stepping`, :mod:`fempm.verification`, :mod:`fempm.io`,
:mod:`fempm.scene` (the run loop), :mod:`fempm.scenes` and :mod:`fempm.studies`
(``docs/architecture.md``). The names below are the public API.
"""

try:  # the PyPI DOLFINx wheel must be imported before dolfinx and petsc4py
    import dolfinx_solver  # noqa: F401
except ImportError:  # conda-forge or distribution DOLFINx
    pass

from fempm.abort import abort_on_error
from fempm.boundary import fixed, friction, prescribed, slip
from fempm.materials import (
    DruckerPrager,
    LinearElastic,
    NeoHookean,
    NewtonianTait,
    VonMises,
)
from fempm.particles.location import CellLocator, OutsideMeshError
from fempm.particles.particle_set import Particles
from fempm.particles.seeding import create_particles
from fempm.scene import Scene, run
import fempm.implicit  # noqa: F401  (registers the implicit step with the solver)
from fempm.stepping import ExplicitSolver, Loads, SimulationError, Solver, StepOptions
from fempm.stepping.contact import Contact
from fempm.transfer.basis import ParticleBasis
from fempm.transfer.domains import make_domain
from fempm.transfer.mapping import SingularMassError, lumped_mass
from fempm.transfer.projection import Projector, interpolate, project
from fempm.verification.errors import particle_errors

__all__ = [
    "CellLocator",
    "Contact",
    "DruckerPrager",
    "ExplicitSolver",
    "LinearElastic",
    "Loads",
    "NeoHookean",
    "NewtonianTait",
    "OutsideMeshError",
    "ParticleBasis",
    "Particles",
    "Projector",
    "Scene",
    "SimulationError",
    "SingularMassError",
    "Solver",
    "StepOptions",
    "VonMises",
    "abort_on_error",
    "create_particles",
    "fixed",
    "friction",
    "interpolate",
    "lumped_mass",
    "make_domain",
    "particle_errors",
    "prescribed",
    "project",
    "run",
    "slip",
]
__version__ = "0.1.0"
