r"""An elastic disk released in a circular bowl: a curved tagged wall (slip, friction or fixed).

The bowl is the lower half of a circle of radius :math:`R` (a polygon of ``segments`` edges,
meshed by gmsh, its arc tagged :data:`WALL_TAG` and held by :func:`fempm.boundary.tagged`),
closed by a lid at :math:`y = 1.3 R` that nothing reaches. A neo-Hookean disk of radius
:math:`r` rests on the arc at ``release`` degrees from the bottom and is released under gravity
:math:`g`. Its centre moves on a circle of radius :math:`\rho_c = R - r`: on a frictionless
(slip) wall it slides without turning, a pendulum of length :math:`\rho_c`, whose period at
amplitude :math:`\theta_0` is

.. math::
    T = 4 \sqrt{\rho_c / g}\; K\big(\sin^2(\theta_0 / 2)\big)

(:math:`K(m)` the complete elliptic integral of the first kind: 1.74 % above
:math:`2\pi\sqrt{\rho_c/g}` at 30 degrees); on a frictional wall that holds it from slipping
(:math:`\mu \ge \tan\theta_0 / 3`) it rolls, the inertia of its turning adding half its
mass: :math:`T \sqrt{3/2}`. Summary:

``period`` (twice the mean time between the centre's crossings of the bowl's axis),
``period_reference`` (the pendulum's, NaN on a fixed wall or where friction lets it slip),
``period_error`` (relative), ``spin`` (the largest :math:`|\omega| r` over the largest
centre speed: 0 sliding, 1 rolling; :math:`\omega` from the angular momentum about the centre)
and ``energy_ratio`` (kinetic + strain + gravity's potential above the bottom at the end, over
its value at the release).
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fempm.boundary.tagged import KINDS, tagged
from fempm.materials.neo_hookean import NeoHookean
from fempm.meshes.generators import tagged_polygon
from fempm.particles.seeding import create_particles
from fempm.scene.definition import Scene, check_counts, check_finite, checked
from fempm.scene.recorder import Recorder
from fempm.scenes.periods import crossing_period
from fempm.stepping.loads import Loads
from fempm.stepping.options import StepOptions

__all__ = ["WALL_TAG", "DiskMotion", "bowl", "pendulum_period"]

#: the tag of the bowl's arc
WALL_TAG = 1


def pendulum_period(length: float, g: float, amplitude: float) -> float:
    r""":math:`4\sqrt{l/g}\,K(\sin^2(\theta_0/2))` for the ``amplitude`` :math:`\theta_0` in
    radians (:math:`K` by the arithmetic-geometric mean)."""
    a, b = 1.0, np.cos(0.5 * amplitude)  # sqrt(1 - m)
    for _ in range(60):
        a, b = 0.5 * (a + b), np.sqrt(a * b)
    return 4.0 * np.sqrt(length / g) * np.pi / (2.0 * a)


class DiskMotion(Recorder):
    """The disk's centre, its velocity and angular velocity about it after every step,
    ``points`` of (t, c_x, c_y, v_x, v_y, omega) (a scene ``watch``; checkpointed). Collective."""

    state_keys = ("points",)

    def __init__(self, particles):
        self.points = [self.state(0.0, particles)]

    @staticmethod
    def state(t: float, p) -> tuple:
        x, v, m = p.x, p.fields.get("v", np.zeros_like(p.x)), p.mass  # (at rest before the solver sets v)
        sums = p.comm.allreduce(np.array([m.sum(), m @ x[:, 0], m @ x[:, 1], m @ v[:, 0], m @ v[:, 1],
                                          m @ (x[:, 0] * v[:, 1] - x[:, 1] * v[:, 0]), m @ np.sum(x * x, axis=1)]))
        M = sums[0]
        c, vc = sums[1:3] / M, sums[3:5] / M
        inertia = sums[6] - M * c @ c
        omega = (sums[5] - M * (c[0] * vc[1] - c[1] * vc[0])) / inertia
        return (t, *c.tolist(), *vc.tolist(), float(omega))

    def __call__(self, solver) -> None:
        self.points.append(self.state(solver.t, solver.particles))


@checked(positive=("radius", "bowl_radius", "rho", "E", "g", "periods"), non_negative=("friction",))
def bowl(*, cells: int = 8, ppc: int = 4, wall: str = "slip", friction: float = 0.3, release: float = 30.0,
         radius: float = 0.2, bowl_radius: float = 1.0, rho: float = 1000.0, E: float = 1.0e6, nu: float = 0.3,
         g: float = 10.0, periods: float = 2.0, segments: int = 48, scheme: str = "MUSL", flip: float = 1.0,
         cfl: float = 0.4, frames: int = 20, mass: str = "lumped", refine: int = 0,
         comm: MPI.Comm = MPI.COMM_WORLD) -> Scene:
    """The disk and its bowl (the module), ``cells`` cells across the disk (the gmsh size
    ``2 radius / cells``), run for ``periods`` of the sliding pendulum.

    Args:
        cells: Cells across the disk.
        ppc: Particles per cell (per triangle).
        wall: The bowl's wall: "slip", "friction" or "fixed".
        friction: The wall's Coulomb coefficient (``wall="friction"``).
        release: The release angle in degrees.
        radius: The disk's radius in m.
        bowl_radius: The bowl's radius in m.
        rho: The density in kg/m^3.
        E: Young's modulus in Pa.
        nu: Poisson's ratio.
        g: Gravity in m/s^2.
        periods: The run's length in periods of the sliding pendulum.
        segments: The straight segments of the bowl's arc.
        refine: Uniform refinements of a coarser gmsh mesh: gmsh meshes at 2^refine times the cell size and every rank splits its triangles refine times (:mod:`fempm.meshes.refinement`; a large mesh made in parallel).

    Raises:
        ValueError: An unknown ``wall``, counts that are not positive, a release outside
            (0, 80) degrees, a disk that does not fit in the bowl, non-finite numbers.
    """
    check_counts(cells=cells, ppc=ppc, segments=segments)
    check_finite(radius=radius, bowl_radius=bowl_radius, rho=rho, E=E, nu=nu, g=g, friction=friction)
    if wall not in KINDS:
        raise ValueError(f"unknown wall={wall!r}; expected one of {', '.join(KINDS)}")
    if not 0.0 < release < 80.0:
        raise ValueError(f"release={release:g} must lie in (0, 80) degrees")
    if not radius < 0.5 * bowl_radius:
        raise ValueError(f"radius={radius:g} must be below half the bowl's radius ({0.5 * bowl_radius:g})")
    R = bowl_radius
    arc = [(R * np.sin(a), R - R * np.cos(a)) for a in np.linspace(-0.5 * np.pi, 0.5 * np.pi, segments + 1)]
    data = tagged_polygon(comm, arc + [(R, 1.3 * R), (-R, 1.3 * R)], 2.0 * radius / cells,
                          [WALL_TAG] * segments + [0, 0, 0], refine=refine)
    theta0 = np.radians(release)
    arm = R - radius  # the centre's path
    centre = np.array([arm * np.sin(theta0), R - arm * np.cos(theta0)])
    p = create_particles(data.mesh, ppc, density=rho,
                         where=lambda x: (x[0] - centre[0]) ** 2 + (x[1] - centre[1]) ** 2 < radius**2)
    motion = DiskMotion(p)
    potential0 = p.comm.allreduce(float(p.mass @ p.x[:, 1])) * g
    sliding = pendulum_period(arm, g, theta0)
    reference = {"slip": sliding, "friction": sliding * np.sqrt(1.5) if friction >= np.tan(theta0) / 3 else np.nan,
                 "fixed": np.nan}[wall]

    def results(scene, solver) -> dict:
        t, cx, cy, vx, vy, omega = np.array(motion.points).T
        q = solver.particles
        energy = solver.energies()["total"] + g * q.comm.allreduce(float(q.mass @ q.x[:, 1]))
        period = crossing_period(t, cx)
        speed = np.hypot(vx, vy).max()
        return {"period": period, "period_reference": reference, "period_error": period / reference - 1.0,
                "spin": float(np.abs(omega).max() * radius / speed) if speed > 0 else 0.0,
                "energy_ratio": energy / potential0}

    def bcs(V):
        return [tagged(V, data.facet_tags, WALL_TAG, wall, friction)]

    params = {"cells": cells, "ppc": ppc, "wall": wall, "friction": friction, "release": release, "radius": radius,
              "bowl_radius": bowl_radius, "rho": rho, "E": E, "nu": nu, "g": g, "periods": periods,
              "segments": segments, "scheme": scheme, "flip": flip, "mass": mass, "cfl": cfl, **({"refine": refine} if refine else {})}
    return Scene(name="bowl", mesh=data.mesh, particles=p, materials=[NeoHookean(E, nu)], t_end=periods * sliding,
                 bcs=bcs, loads=Loads(body_force=(0.0, -g)), options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl),
                 frames=frames, params=params, results=results, watch=motion)
