"""Particle-to-grid and grid-to-particle transfer: the basis at the particles and their
domains, exact box averages, the mass-weighted projection (lumped, consistent, FMPM), the
singular-mass test, and the particle basis functions."""

from fempm.transfer.centres import NodalCentres
from fempm.transfer.mapping import (
    SUPPORT_TOL,
    WEIGHTS,
    SingularMassError,
    cell_blocks,
    consistent_mass_matrix,
    lumped_mass,
    mass_centres,
    nodal_centroids,
    p2g,
    p2g_gradients,
    particle_weights,
    sum_over_ranks,
)
from fempm.transfer.projection import MassMode, Projector, interpolate, project

__all__ = [
    "MassMode",
    "NodalCentres",
    "Projector",
    "SUPPORT_TOL",
    "SingularMassError",
    "WEIGHTS",
    "cell_blocks",
    "consistent_mass_matrix",
    "interpolate",
    "lumped_mass",
    "mass_centres",
    "nodal_centroids",
    "p2g",
    "p2g_gradients",
    "particle_weights",
    "project",
    "sum_over_ranks",
]
