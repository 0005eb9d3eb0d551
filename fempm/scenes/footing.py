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
"""

from __future__ import annotations

from fempm.meshes import structured as dm
import numpy as np
from mpi4py import MPI

from fempm.boundary.walls import fixed, slip
from fempm.colliders.collider import Collider
from fempm.colliders.shapes import box
from fempm.materials.von_mises import VonMises
from fempm.particles.seeding import create_particles
from fempm.scene.definition import Scene, check_counts, check_finite, checked
from fempm.scene.recorder import Recorder
from fempm.stepping.options import StepOptions

__all__ = ["LAYER", "PressureCurve", "footing", "prandtl"]

#: the layer's width and depth over the footing's width
LAYER = (5.0, 2.0)
#: the room above the layer, over the footing's width (heave)
ROOM = 0.5


class PressureCurve(Recorder):
    """The footing's (penetration / width, mean contact pressure) after every step, ``points``
    (a scene ``watch``: the collider's displacement and force; checkpointed)."""

    state_keys = ("points",)

    def __init__(self, width: float):
        self.width = width
        self.points: list[tuple[float, float]] = []

    def __call__(self, solver) -> None:
        c = solver.collisions
        self.points.append((-c.displacement[0][1] / self.width, c.force[0][1] / self.width))


def prandtl(yield_stress: float) -> float:
    r"""Prandtl's bearing pressure :math:`(2 + \pi)\, \sigma_y / \sqrt3`."""
    return float((2.0 + np.pi) * yield_stress / np.sqrt(3.0))


def _ramp(speed: float, t_ramp: float):
    """The footing's velocity: 0 to ``-speed`` (downwards) by a smoothstep over ``t_ramp``."""
    def velocity(t: float) -> np.ndarray:
        s = min(max(t / t_ramp, 0.0), 1.0)
        return np.array([0.0, -speed * s * s * (3.0 - 2.0 * s)])
    return velocity


@checked(positive=("width", "E", "yield_stress", "rho"))
def footing(*, cells: int = 8, depth: float = 0.1, width: float = 1.0, E: float = 1.0e7, nu: float = 0.3,
            yield_stress: float = 1.0e4 * np.sqrt(3.0), rho: float = 1000.0, speed: float = 0.2, ppc: int = 4,
            scheme: str = "MUSL", flip: float = 0.95, cfl: float = 0.4, frames: int = 0,
            mass: str = "lumped", comm: MPI.Comm = MPI.COMM_WORLD) -> Scene:
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
        ppc: Particles per cell, a lattice.

    Raises:
        ValueError: Counts that are not positive, a depth outside (0, 1], non-finite numbers.
    """
    check_counts(cells=cells, ppc=ppc)
    check_finite(width=width, E=E, nu=nu, yield_stress=yield_stress, rho=rho, speed=speed)
    if not 0.0 < depth <= 1.0:
        raise ValueError(f"depth={depth:g} must lie in (0, 1] (the penetration over the footing's width)")
    if not speed > 0.0:
        raise ValueError(f"speed={speed:g} must be > 0")
    h = width / cells
    half, layer = 0.5 * LAYER[0] * width, LAYER[1] * width
    top = layer + ROOM * width
    mesh = dm.create_rectangle(comm, [[-half, 0.0], [half, top]], [int(LAYER[0] * cells), round(top / h)],
                               dm.CellType.quadrilateral)
    p = create_particles(mesh, ppc, density=rho, cells=lambda x: x[1] < layer - 1e-9 * h)
    # the time to penetrate: the ramp's quarter at half the speed on average, then the full speed
    t_end = depth * width / speed / (1.0 - 0.125)
    shape = box((-0.5 * width, layer), (0.5 * width, top + width))
    law = VonMises(E, nu, yield_stress)
    curve = PressureCurve(width)

    def results(scene, solver) -> dict:
        pen, q = np.array(curve.points).T if curve.points else (np.zeros(1), np.zeros(1))
        late = pen >= 0.9 * pen[-1]
        q_end = float(np.mean(q[late]))
        qu = prandtl(yield_stress)
        return {"bearing_pressure": q_end, "prandtl": qu, "bearing_ratio": q_end / qu,
                "penetration": float(pen[-1])}

    def bcs(V):
        return [fixed(V, lambda x: np.isclose(x[1], 0.0)),
                slip(V, lambda x: np.isclose(np.abs(x[0]), half), (1.0, 0.0))]

    params = {"cells": cells, "depth": depth, "width": width, "E": E, "nu": nu, "yield_stress": yield_stress,
              "rho": rho, "speed": speed, "ppc": ppc, "scheme": scheme, "flip": flip, "mass": mass, "cfl": cfl}
    return Scene(name="footing", mesh=mesh, particles=p, materials=[law], t_end=t_end, bcs=bcs,
                 options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl), frames=frames, params=params,
                 results=results, watch=curve,
                 colliders=[Collider(shape, velocity=_ramp(speed, 0.25 * t_end))])
