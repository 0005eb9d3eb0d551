"""Particles: the struct of arrays that moves between ranks, seeding, point location in the
background mesh, migration, partition, halo of remote cells, and the geometry of particle
domains given by their corners."""

from fempm.particles.particle_set import OutsidePolicy, Particles

__all__ = [
    "OutsidePolicy",
    "Particles",
]
