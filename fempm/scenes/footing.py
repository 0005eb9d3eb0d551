r"""A rigid strip footing pushed into a weightless von Mises layer (plane strain): Prandtl's
bearing capacity.

A smooth rigid footing of width :math:`B` (a box collider, :class:`fempm.colliders.Collider`)
is pushed vertically into the surface of a layer :math:`5B` wide and :math:`2B` deep (fixed
base, smooth sides) of a weightless elastic-perfectly plastic von Mises material of yield stress
:math:`\sigma_y`. In plane strain the von Mises criterion is Tresca's with the cohesion
:math:`c = \sigma_y/\sqrt3`, and the footing's mean contact pressure reaches Prandtl's limit
(1920; the same for a rough footing, Hill's mechanism),

.. math::
    q_u = (2 + \pi)\, c .

The footing moves at the speed ``speed`` (m/s), reached over the first quarter of the run by a
smooth ramp (a sudden start sends a stress wave of :math:`\rho c_p v` into the layer), until it
has penetrated ``depth`` :math:`\times B`. Results: ``bearing_pressure``, the mean of the
footing's reaction over :math:`B` over the last tenth of the penetration (from the collider's
force, :attr:`fempm.colliders.grid.ColliderContact.force`, kept by the scene's ``watch``, a
:class:`PressureCurve`), ``prandtl``, :math:`(2 + \pi) c`,
and their ratio ``bearing_ratio``; ``energies.csv`` holds the force and the displacement of
every step (``collider_force_0_y``, ``collider_displacement_0_y``: the force-penetration curve).

With ``dim=3`` the footing is square, :math:`B \times B`, on a layer :math:`5B \times 5B` in plan
and :math:`2B` deep (y up, smooth sides all round), on hexahedra; the pressure is the force over
:math:`B^2`, and ``bearing_ratio`` is taken over Skempton's (1951) square footing,
:math:`q_u \approx 6.2\, c` (``skempton``; a shape factor of 1.2 on Prandtl's strip: an
engineering value, not an exact limit load).
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fempm.boundary.walls import fixed, slip
from fempm.colliders.collider import Collider
from fempm.colliders.shapes import box
from fempm.materials.von_mises import VonMises
from fempm.particles.seeding import create_particles
from fempm.scene.definition import Scene, check_counts, check_finite, checked
from fempm.scenes.dims import axis, block_mesh, check_dim, lattice_ppc
from fempm.scene.recorder import Recorder
from fempm.stepping.options import StepOptions

__all__ = ["LAYER", "PressureCurve", "footing", "prandtl", "skempton"]

#: the layer's width and depth over the footing's width
LAYER = (5.0, 2.0)
#: the room above the layer, over the footing's width (heave)
ROOM = 0.5


class PressureCurve(Recorder):
    """The footing's (penetration / width, mean contact pressure) after every step, ``points``
    (a scene ``watch``: the collider's displacement and force; checkpointed)."""

    state_keys = ("points",)

    def __init__(self, width: float, dim: int = 2):
        self.width, self.area = width, width ** (dim - 1)
        self.points: list[tuple[float, float]] = []

    def __call__(self, solver) -> None:
        c = solver.collisions
        self.points.append((-c.displacement[0][1] / self.width, c.force[0][1] / self.area))


def prandtl(yield_stress: float) -> float:
    r"""Prandtl's bearing pressure :math:`(2 + \pi)\, \sigma_y / \sqrt3`."""
    return float((2.0 + np.pi) * yield_stress / np.sqrt(3.0))


def skempton(yield_stress: float) -> float:
    r"""Skempton's bearing pressure of a square surface footing, :math:`6.2\, \sigma_y / \sqrt3`."""
    return float(6.2 * yield_stress / np.sqrt(3.0))


def _ramp(speed: float, t_ramp: float, dim: int = 2):
    """The footing's velocity: 0 to ``-speed`` (downwards) by a smoothstep over ``t_ramp``."""
    def velocity(t: float) -> np.ndarray:
        s = min(max(t / t_ramp, 0.0), 1.0)
        return np.array(axis(1, dim, -speed * s * s * (3.0 - 2.0 * s)))
    return velocity


@checked(positive=("width", "E", "yield_stress", "rho"))
def footing(*, cells: int = 8, depth: float = 0.1, width: float = 1.0, E: float = 1.0e7, nu: float = 0.3,
            yield_stress: float = 1.0e4 * np.sqrt(3.0), rho: float = 1000.0, speed: float = 0.2, ppc: int | None = None,
            scheme: str = "MUSL", flip: float = 0.95, cfl: float = 0.4, frames: int = 0,
            mass: str = "lumped", dim: int = 2, comm: MPI.Comm = MPI.COMM_WORLD) -> Scene:
    """The footing of the module with ``cells`` cells across its width.

    Args:
        cells: Cells across the footing's width.
        depth: The penetration at the end, in footing widths (0, 1].
        width: The footing's width B in m.
        E: Young's modulus in Pa.
        nu: Poisson's ratio.
        yield_stress: The von Mises yield stress in Pa (the cohesion is yield_stress / sqrt(3)).
        rho: The density in kg/m^3.
        speed: The footing's speed in m/s.
        ppc: Particles per cell, a lattice (None: 4 in 2D, 8 in 3D).
        dim: 2 (a strip footing, plane strain) or 3 (a square footing).

    Raises:
        ValueError: Counts that are not positive, a depth outside (0, 1], non-finite numbers.
    """
    dim = check_dim(dim)
    ppc = lattice_ppc(ppc, dim)
    check_counts(cells=cells, ppc=ppc)
    check_finite(width=width, E=E, nu=nu, yield_stress=yield_stress, rho=rho, speed=speed)
    if not 0.0 < depth <= 1.0:
        raise ValueError(f"depth={depth:g} must lie in (0, 1] (the penetration over the footing's width)")
    if not speed > 0.0:
        raise ValueError(f"speed={speed:g} must be > 0")
    h = width / cells
    half, layer = 0.5 * LAYER[0] * width, LAYER[1] * width
    top = layer + ROOM * width
    across, up = int(LAYER[0] * cells), round(top / h)
    lo, hi, n = [-half, 0.0, -half][:dim], [half, top, half][:dim], [across, up, across][:dim]
    mesh = block_mesh(comm, lo, hi, n)
    p = create_particles(mesh, ppc, density=rho, cells=lambda x: x[1] < layer - 1e-9 * h)
    # the time to penetrate: the ramp's quarter at half the speed on average, then the full speed
    t_end = depth * width / speed / (1.0 - 0.125)
    shape = box((-0.5 * width, layer, -0.5 * width)[:dim], (0.5 * width, top + width, 0.5 * width)[:dim])
    law = VonMises(E, nu, yield_stress)
    curve = PressureCurve(width, dim)

    def results(scene, solver) -> dict:
        pen, q = np.array(curve.points).T if curve.points else (np.zeros(1), np.zeros(1))
        late = pen >= 0.9 * pen[-1]
        q_end = float(np.mean(q[late]))
        qu = prandtl(yield_stress) if dim == 2 else skempton(yield_stress)
        return {"bearing_pressure": q_end, "prandtl": prandtl(yield_stress), "bearing_ratio": q_end / qu,
                "penetration": float(pen[-1]), **({"skempton": qu} if dim == 3 else {})}

    def bcs(V):
        sides = [slip(V, lambda x, k=k: np.isclose(np.abs(x[k]), half), axis(k, dim)) for k in (0, 2)[:dim - 1]]
        return [fixed(V, lambda x: np.isclose(x[1], 0.0)), *sides]

    params = {"cells": cells, "depth": depth, "width": width, "E": E, "nu": nu, "yield_stress": yield_stress,
              "rho": rho, "speed": speed, "ppc": ppc, "scheme": scheme, "flip": flip, "mass": mass, "cfl": cfl,
              **({"dim": dim} if dim == 3 else {})}
    return Scene(name="footing", mesh=mesh, particles=p, materials=[law], t_end=t_end, bcs=bcs,
                 options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl), frames=frames, params=params,
                 results=results, watch=curve,
                 colliders=[Collider(shape, velocity=_ramp(speed, 0.25 * t_end, dim))])
