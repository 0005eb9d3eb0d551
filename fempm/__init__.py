"""fempm: the Material Point Method on DOLFINx background meshes.

The particle-to-grid map is the mass-weighted least-squares (Galerkin) projection of the
particle data onto a DOLFINx finite element space, with the consistent mass matrix
(PETSc Mat + KSP) or its lumped (row-sum) approximation.
"""

try:  # the PyPI DOLFINx wheel must be imported before dolfinx and petsc4py
    import dolfinx_solver  # noqa: F401
except ImportError:  # conda-forge or distribution DOLFINx
    pass

from fempm.basis import ParticleBasis
from fempm.location import CellLocator, OutsideMeshError
from fempm.particles import Particles
from fempm.seeding import create_particles
from fempm.transfer import Projector, SingularMassError, interpolate, lumped_mass, project

__all__ = [
    "CellLocator",
    "OutsideMeshError",
    "ParticleBasis",
    "Particles",
    "Projector",
    "SingularMassError",
    "create_particles",
    "interpolate",
    "lumped_mass",
    "project",
]
__version__ = "0.1.0"
