"""The checks of a particle state that open a step: the fields' shapes, finite values, body
indices, and the step's arguments."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt

from fempm.kernels.finite import nonfinite
from fempm.particles.particle_set import Particles

__all__ = ["check_bodies", "check_fields", "check_step_arguments", "nonfinite_particles"]


def check_fields(particles: Particles, materials: Sequence) -> None:
    """Every particle array has a row per particle, and the fields the step reads their shapes
    (those of the laws' internal variables included). Collective."""
    d = particles.gdim
    shapes = {"v": (d,), "F": (d, d), "sigma": (d, d), "volume0": (), "body": (), "X0": (d,)}
    for mat in materials:
        shapes.update({h.name: h.shape_for(d) for h in mat.history})
    particles.check_fields(shapes)


def check_bodies(particles: Particles, materials: Sequence, ids: Callable[[npt.NDArray], list]) -> None:
    """Every particle's body indexes a material, else a ValueError naming the first particles
    (``ids`` of a mask). Collective."""
    body = particles.fields["body"]
    bad = (body < 0) | (body >= len(materials))
    if particles.comm.allreduce(int(np.count_nonzero(bad))):
        raise ValueError(f"particle body index outside the {len(materials)} material(s) at particle(s) {ids(bad)}")


def nonfinite_particles(particles: Particles) -> npt.NDArray[np.bool_]:
    r"""The particles whose position, stress or kinetic energy density :math:`v_p \cdot v_p`
    (hence velocity) is not finite (this rank's)."""
    f = particles.fields
    return nonfinite(particles.x, f["v"], f["sigma"])  # (compiled, fempm.kernels.finite)


def check_step_arguments(particles: Particles, dt: float | None, dt_max: float) -> None:
    """A given ``dt`` positive and finite, ``dt_max`` positive, particles on some rank."""
    if dt is not None and not (0.0 < dt < np.inf):
        raise ValueError(f"step: dt={dt} must be a positive, finite time step (or None for the stable one)")
    if not dt_max > 0.0:
        raise ValueError(f"step: dt_max={dt_max} must be positive")
    if particles.num_global == 0:
        raise ValueError("step: there are no particles (the particle set is empty on every rank)")
