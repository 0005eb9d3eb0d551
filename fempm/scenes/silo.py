r"""Granular flow out of a hopper onto a floor (plane strain, mu(I) or Drucker-Prager).

A wedge hopper with walls at ``half_angle`` :math:`\alpha` from the vertical, an outlet of width
``outlet`` :math:`W_o` at the height :math:`y_o` = :data:`OUTLET_HEIGHT`, is filled to ``fill``
above the outlet with a cohesionless granular material at rest; the outlet is open at
:math:`t = 0`. The material falls onto a floor of width :data:`FLOOR` under the outlet, heaps on
it and spills over its edges out of the mesh, where it is removed (``outside="remove"``,
:mod:`fempm.stepping.outside`). The mesh is a gmsh triangulation of the hopper and the chamber
below it (:func:`fempm.meshes.generators.tagged_polygon`): the hopper's walls are the tagged
boundary :data:`WALL_TAG` held by Coulomb friction ``wall_friction`` against their facet normals
(:func:`fempm.boundary.tagged`), the floor :data:`FLOOR_TAG` with ``floor_friction``; the
chamber's sides and the bottom beside the floor are open.

Results: ``discharge_rate``, the mass per second (per unit thickness) leaving the hopper over the
steady part of the flow (the slope of a least-squares line through the hopper's mass, kept by
the scene's ``watch``, a :class:`HopperMass`, while it
holds between 85 % and 35 % of its fill; NaN if the run ends before), ``beverloo_coefficient``
(:func:`beverloo_coefficient`), ``hopper_mass`` (the mass still above the outlet at the end) and
the run's ``removed`` entry (the mass that left the mesh).

The grains follow the :math:`\mu(I)` rheology by default (:class:`fempm.materials.MuI`,
``law="mu-i"``), or Drucker-Prager (``law="dp"``). The walls leave their ends at the outlet's
lips free (:func:`fempm.boundary.tagged.open_ends`).
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fempm.boundary.tagged import tagged
from fempm.materials.drucker_prager import DruckerPrager
from fempm.materials.mu_i import MuI
from fempm.meshes.generators import tagged_polygon
from fempm.particles.seeding import create_particles
from fempm.scene.definition import Scene, check_counts, check_finite, checked
from fempm.scene.recorder import Recorder
from fempm.stepping.loads import Loads
from fempm.stepping.options import StepOptions

__all__ = ["FLOOR", "FLOOR_TAG", "LAWS", "OUTLET_HEIGHT", "WALL_TAG", "HopperMass", "beverloo_coefficient",
           "discharge_rate", "silo"]

#: the facet tags of the hopper's walls and of the floor
WALL_TAG, FLOOR_TAG = 2, 1
#: the outlet's height above the floor, the floor's and the chamber's widths, the hopper's top width (m)
OUTLET_HEIGHT, FLOOR, CHAMBER, TOP = 0.2, 0.4, 1.0, 0.5
#: the grains' laws the scene takes (``law``)
LAWS = ("mu-i", "dp")
#: the window of the hopper's mass (fractions of its fill) over which the discharge is steady
WINDOW = (0.85, 0.35)


class HopperMass(Recorder):
    """The mass above the outlet, (t, mass) from the fill at t = 0 and after every step,
    ``points`` (a scene ``watch``; checkpointed). Collective."""

    state_keys = ("points",)

    def __init__(self, particles):
        self.points = [(0.0, self.mass(particles))]  # the fill: all above the outlet

    @staticmethod
    def mass(particles) -> float:
        return particles.comm.allreduce(float(particles.mass[particles.x[:, 1] > OUTLET_HEIGHT].sum()))

    def __call__(self, solver) -> None:
        self.points.append((solver.t, self.mass(solver.particles)))


def discharge_rate(t: np.ndarray, mass: np.ndarray) -> float:
    """The steady discharge: minus the slope of the hopper's ``mass`` over time ``t`` while it
    lies within :data:`WINDOW` of the first value (NaN with fewer than 3 such samples)."""
    steady = (mass <= WINDOW[0] * mass[0]) & (mass >= WINDOW[1] * mass[0])
    if np.count_nonzero(steady) < 3:
        return float("nan")
    return float(-np.polyfit(t[steady], mass[steady], 1)[0])


def beverloo_coefficient(rate: float, rho: float, g: float, outlet: float) -> float:
    r"""The coefficient :math:`C` of Beverloo's law in a plane hopper (per unit thickness),
    :math:`W = C \rho \sqrt{g}\, D^{3/2}`, of a discharge ``rate`` :math:`W` through an outlet
    :math:`D` (the grains' size correction :math:`D - k d` left out: :math:`d \ll D`)."""
    return float(rate / (rho * np.sqrt(g) * outlet**1.5)) if g > 0 else float("nan")


def _outline(outlet: float, half_angle: float, width: float = TOP) -> tuple[np.ndarray, list[int], float]:
    """The polygon of the hopper (top ``width``) and the chamber, its edge tags, and the
    hopper's top height."""
    top = OUTLET_HEIGHT + 0.5 * (width - outlet) / np.tan(np.radians(half_angle))
    yo, wo, wc, wf, wt = OUTLET_HEIGHT, 0.5 * outlet, 0.5 * CHAMBER, 0.5 * FLOOR, 0.5 * width
    vertices = np.array([[-wc, 0.0], [-wf, 0.0], [wf, 0.0], [wc, 0.0], [wc, yo], [wo, yo], [wt, top], [-wt, top],
                         [-wo, yo], [-wc, yo]])
    tags = [0, FLOOR_TAG, 0, 0, 0, WALL_TAG, 0, WALL_TAG, 0, 0]
    return vertices, tags, top


@checked(positive=("outlet", "half_angle", "fill", "rho", "E", "friction_angle", "grain_diameter", "width"),
         non_negative=("wall_friction", "floor_friction", "g"))
def silo(*, cells: int = 5, outlet: float = 0.1, half_angle: float = 30.0, fill: float = 0.3, ppc: int = 4,
         rho: float = 2000.0, E: float = 2.0e6, nu: float = 0.3, friction_angle: float = 30.0,
         wall_friction: float = 0.3, floor_friction: float = 0.5, g: float = 9.81, t_end: float = 1.0,
         scheme: str = "MUSL", flip: float = 0.99, cfl: float = 0.4, frames: int = 20, law: str = "mu-i",
         grain_diameter: float = 0.53e-3, width: float = TOP, floor: bool = True,
         mass: str = "lumped", refine: int = 0, comm: MPI.Comm = MPI.COMM_WORLD) -> Scene:
    r"""The silo of the module, ``cells`` cells across the outlet (the gmsh size ``outlet / cells``),
    the grains a ``law`` of :data:`LAWS`: ``"mu-i"`` the :math:`\mu(I)` rheology
    (:class:`fempm.materials.MuI`, Jop et al.'s glass beads of ``grain_diameter``), ``"dp"`` Drucker-Prager
    with ``friction_angle``; ``width`` the hopper's top width (a wider hopper holds a taller
    fill: the steady part of the discharge lasts longer). ``floor=False`` leaves the floor open:
    the grains fall out of the mesh and are removed, and no heap under the outlet chokes a large
    discharge (Beverloo's regime; choose ``t_end`` before the hopper is empty, or the run ends
    with every particle gone).

    Args:
        cells: Cells across the outlet.
        outlet: The outlet's width D in m.
        half_angle: The hopper walls' angle from the vertical in degrees.
        fill: The fill's height above the outlet in m.
        ppc: Particles per cell (per triangle).
        rho: The bulk density in kg/m^3.
        E: Young's modulus in Pa.
        nu: Poisson's ratio.
        friction_angle: Drucker-Prager's friction angle in degrees (``law="dp"``).
        wall_friction: The hopper walls' Coulomb coefficient.
        floor_friction: The floor's Coulomb coefficient.
        g: Gravity in m/s^2.
        t_end: The end time in s.
        law: "mu-i" (the mu(I) rheology) or "dp" (Drucker-Prager).
        grain_diameter: The grains' diameter in m (``law="mu-i"``).
        width: The hopper's top width in m.
        floor: A floor under the outlet (false: the grains fall out of the mesh).
        refine: Uniform refinements of a coarser gmsh mesh: gmsh meshes at 2^refine times the cell size and every rank splits its triangles refine times (:mod:`fempm.meshes.refinement`; a large mesh made in parallel).

    Raises:
        ValueError: Counts that are not positive, a half-angle outside (0, 60) degrees, a fill
            above the hopper's top or not positive, non-finite numbers.
    """
    check_counts(cells=cells, ppc=ppc)
    if law not in LAWS:
        raise ValueError(f"unknown option law={law!r}; expected one of {', '.join(LAWS)}")
    check_finite(outlet=outlet, fill=fill, rho=rho, E=E, nu=nu, g=g, t_end=t_end)
    if not 0.0 < half_angle < 60.0:
        raise ValueError(f"half_angle={half_angle:g} must lie in (0, 60) degrees")
    if not 0.0 < outlet < width:
        raise ValueError(f"outlet={outlet:g} must lie in (0, {width:g}) (the hopper's top width)")
    vertices, tags, top = _outline(outlet, half_angle, width)
    if not 0.0 < fill < top - OUTLET_HEIGHT:
        raise ValueError(f"fill={fill:g} must lie in (0, {top - OUTLET_HEIGHT:.4g}) (the hopper's height)")
    data = tagged_polygon(comm, vertices, outlet / cells, tags, refine=refine)
    tan = np.tan(np.radians(half_angle))

    def inside(x):
        y = x[1] - OUTLET_HEIGHT
        return (y > 0.0) & (y < fill) & (np.abs(x[0]) < 0.5 * outlet + y * tan)

    p = create_particles(data.mesh, ppc, density=rho, where=inside)
    hopper = HopperMass(p)

    def results(scene, solver) -> dict:
        t, m = np.array(hopper.points).T
        rate = discharge_rate(t, m)
        return {"discharge_rate": rate, "hopper_mass": float(m[-1]),
                "beverloo_coefficient": beverloo_coefficient(rate, rho, g, outlet)}

    def bcs(V):
        walls = [tagged(V, data.facet_tags, WALL_TAG, "friction", wall_friction)]
        return walls + ([tagged(V, data.facet_tags, FLOOR_TAG, "friction", floor_friction)] if floor else [])

    params = {"cells": cells, "outlet": outlet, "half_angle": half_angle, "fill": fill, "ppc": ppc, "rho": rho,
              "E": E, "nu": nu, "friction_angle": friction_angle, "wall_friction": wall_friction,
              "floor_friction": floor_friction, "g": g, "scheme": scheme, "flip": flip, "mass": mass, "cfl": cfl, "law": law,
              "grain_diameter": grain_diameter, "width": width, "floor": floor, **({"refine": refine} if refine else {})}
    material = MuI(E, nu, grain_diameter=grain_diameter) if law == "mu-i" else DruckerPrager(E, nu, friction_angle)
    return Scene(name="silo", mesh=data.mesh, particles=p, materials=[material],
                 t_end=t_end, bcs=bcs, loads=Loads(body_force=(0.0, -g)),
                 options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl), frames=frames, params=params,
                 results=results, watch=hopper, outside="remove")
