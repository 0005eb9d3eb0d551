r"""A block sliding or a disk rolling down a frictional incline (plane strain, elastic).

The incline is the grid boundary :math:`y = 0` with Coulomb friction ``friction`` :math:`\mu`
(:func:`fempm.boundary.friction`), or a rigid body in frictional contact (``plane="rigid"``),
in the frame of the slope: :math:`x` runs down it and gravity is
:math:`g (\sin\theta, -\cos\theta)` for the slope angle :math:`\theta` (``angle``, degrees),
which is the inclined plane itself, rotated. With ``plane="tagged"`` the slope is not a grid
axis: the mesh is a gmsh triangulation of the same region turned by :math:`\theta` (gravity
:math:`(0, -g)`), whose floor is the tagged boundary :data:`FLOOR_TAG` held by
:func:`fempm.boundary.tagged` (Coulomb friction against its facet normals). With
``plane="collider"`` the slope is a plane collider through the origin turned by :math:`\theta`
(:class:`fempm.colliders.Collider`, gravity :math:`(0, -g)`), on the slope's structured grid
turned with it (``turned=True``) or on an axis-aligned grid that it cuts at :math:`\theta`
(docs/colliders.md). The body is elastic and objective under the
disk's large rotation: hypoelastic with the Jaumann rate (:class:`fempm.materials.VonMises`
without a yield stress), whose strain energy comes from the stress, so that a body starting
under stress has it. It starts at rest on the plane:

* ``block``: :math:`2s \times s` (``size`` :math:`s`), starting with the stress of a layer at
  rest on the slope, :math:`\sigma_{yy} = -\rho g \cos\theta\,(s - y)`,
  :math:`\sigma_{xy} = \rho g \sin\theta\,(s - y)` (without it the elastic block bounces
  on the plane and a block that should stick slips while it is off it); it slides with
  :math:`a = g (\sin\theta - \mu \cos\theta)` where :math:`\tan\theta > \mu`, and sticks
  (:math:`a = 0`) otherwise;
* ``disk``: radius :math:`s`; it rolls without slipping, :math:`a = \tfrac23 g \sin\theta`
  (a uniform disk, :math:`I = \tfrac12 m s^2`), where :math:`\mu \ge \tfrac13 \tan\theta`, and
  slides with :math:`a = g (\sin\theta - \mu \cos\theta)` otherwise.

The defaults are what the analytic accelerations take, with the measurements behind each in
docs/contact.md ("The incline", "The sliding block", "The rolling threshold on the grid"):

* the plane holds only the nodes the body touches (its nodal centre of mass within ``gap``
  cells, :class:`fempm.boundary.Friction`) and shares its normal impulse over them by depth,
  else it stops the disk's rotation;
* the disk has 4 x 4 particles per cell (with 2 x 2 its staircase of particles bounces as it
  rolls) and pure FLIP (PIC brakes rolling);
* the block blends 30 % of PIC (``flip=0.7``): with pure FLIP the frictional sliding of an
  elastic block is unstable near the friction angle and nothing damps it.

The results (:func:`slope_acceleration`): ``acceleration``, the along-slope acceleration of the
body's centre of mass once it moves (:math:`2 c_2` of the least-squares fit
:math:`x_c(t) = c_0 + c_1 t + c_2 t^2` over the second half of the run, after the body has
settled on the plane), and ``analytic``, the value above.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fempm.boundary.tagged import tagged
from fempm.boundary.walls import friction as friction_wall
from fempm.colliders.collider import Collider
from fempm.colliders.shapes import plane as collider_plane
from fempm.materials.von_mises import VonMises
from fempm.meshes import structured as dm
from fempm.meshes.generators import tagged_polygon
from fempm.particles.seeding import create_particles, per_direction
from fempm.scene.definition import Scene, check_counts, checked
from fempm.scene.recorder import Recorder
from fempm.stepping.contact import Contact
from fempm.stepping.loads import Loads
from fempm.stepping.options import StepOptions

__all__ = [
    "BLOCK_FLIP", "BODIES", "FLOOR_TAG", "PLANES", "RIGID_MASS_CUTOFF", "analytic_acceleration", "incline",
    "slope_acceleration",
]

BODIES = ("block", "disk")
#: the PIC/FLIP blend of the block by default: pure FLIP lets the frictional sliding of the
#: elastic block go unstable (see the module)
BLOCK_FLIP = 0.7
PLANES = ("grid", "rigid", "tagged", "collider")
#: the facet tag of the slope with ``plane="tagged"``
FLOOR_TAG = 1
#: the contact's force cut-off with a rigid plane: with the default 1 % the rolling disk's
#: sparsely filled nodes keep their mapped velocity, and its energy grows by 20 % in 0.34 s
RIGID_MASS_CUTOFF = 1e-4


def _depth(ppc: int) -> float:
    """How far below a node on its surface a layer of ``ppc`` particles per cell (a square lattice)
    has its nodal centre of mass, in cells (1/3 for a continuum, 0.375 for 2)."""
    n = per_direction(ppc, 2)
    y = (np.arange(n) + 0.5) / n
    return float(np.sum((1.0 - y) * y) / np.sum(1.0 - y))


def analytic_acceleration(body: str, angle: float, mu: float, g: float = 9.81) -> float:
    """The along-slope acceleration of the module's rigid-body solution."""
    th = np.radians(angle)
    sliding = g * (np.sin(th) - mu * np.cos(th))
    if body == "block":
        return float(max(sliding, 0.0))
    return float(2.0 / 3.0 * g * np.sin(th) if mu >= np.tan(th) / 3.0 else sliding)


class _Track(Recorder):
    """The body's centre of mass along the slope (the unit vector ``down``) after every step (a
    scene ``watch``; checkpointed)."""

    state_keys = ("t", "x")

    def __init__(self, down=(1.0, 0.0)):
        self.down = np.asarray(down, dtype=float)
        self.t: list[float] = []
        self.x: list[float] = []

    def __call__(self, solver) -> None:
        p = solver.particles
        mass = np.where(p.fields["plane"] == 0, p.mass, 0.0)  # the body, not a rigid plane
        sums = np.array([mass @ (p.x[:, :2] @ self.down), mass.sum()])
        p.comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
        self.t.append(solver.t)
        self.x.append(sums[0] / sums[1])


def slope_acceleration(track: _Track, t_end: float) -> float:
    """:math:`2 c_2` of the quadratic fit of the tracked centre of mass over the second half of
    the run."""
    t, x = np.array(track.t), np.array(track.x)
    late = t >= 0.5 * t_end
    if np.count_nonzero(late) < 3:
        return float("nan")
    return float(2.0 * np.polyfit(t[late], x[late], 2)[0])


@checked(positive=("size", "E", "rho"), non_negative=("gap", "friction", "g"))
def incline(
    body: str = "block", angle: float = 30.0, friction: float = 0.2, *, cells: int = 8, ppc: int | None = None,
    size: float = 0.1, E: float = 1.0e6, nu: float = 0.3, rho: float = 1000.0, g: float = 9.81,
    t_end: float | None = None, scheme: str = "MUSL", flip: float | None = None, cfl: float = 0.4, frames: int = 10,
    plane: str = "grid", gap: float | None = None, turned: bool = True, mass: str = "lumped", refine: int = 0,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> Scene:
    """The incline of the module: ``cells`` cells across ``size``, ``ppc`` particles per
    cell, a square lattice (default 4 = 2 x 2 for the block, 16 = 4 x 4 for the disk, whose
    staircase of particles rolls within 2 % only at that spacing). ``flip``: the PIC/FLIP
    blend, default 0.7 for the block and 1.0 for the disk (see the module). ``t_end``
    defaults to the time the body takes to travel three sizes at
    :math:`g \\sin\\theta` (at least 0.2 s). ``plane``: ``grid``, the frictional grid boundary
    :math:`y = 0` holding the nodes the body touches (its nodal centre of mass within ``gap``
    cells of the plane; 0, the block's default: every node moving into it; 0.5 the disk's),
    or ``rigid``, a rigid layer of particles two cells thick under :math:`y = 0` in frictional
    contact with the body
    (:class:`fempm.stepping.contact.Contact` with ``rigid=(1,)``, the gap measured from the layer's own
    nodal centre of mass, which lies :func:`_depth` cells under its surface), or ``tagged``, the
    tagged floor of a turned gmsh triangle mesh of size ``size / cells`` (the block; every node
    moving into the floor held, no gap), or ``collider``, a plane collider (the gap ``gap``
    cells, default half a cell) on the slope's grid turned with it (``turned``) or on an
    axis-aligned grid.

    Args:
        body: "block" (slides or sticks) or "disk" (rolls or slides).
        angle: The slope's angle in degrees.
        friction: The Coulomb coefficient between the body and the plane.
        cells: Cells across ``size``.
        ppc: Particles per cell, a lattice (None: 4 for the block, 16 for the disk).
        size: The block's height or the disk's radius in m.
        E: Young's modulus in Pa.
        nu: Poisson's ratio.
        rho: The density in kg/m^3.
        g: Gravity in m/s^2.
        t_end: The end time in s (None: the time to travel three sizes, at least 0.2 s).
        flip: The PIC/FLIP blend (None: 0.7 for the block, 1 for the disk).
        plane: "grid" (the grid's frictional boundary), "rigid" (a rigid layer of particles),
            "tagged" (a turned gmsh mesh's tagged floor) or "collider" (a plane collider).
        gap: How near, in cells, a node's centre of mass must come to the plane to touch it
            (None: 0 for the block, 0.5 for the disk).
        turned: The collider plane on the slope's turned grid (else an axis-aligned one).
        refine: Uniform refinements of a coarser gmsh mesh: gmsh meshes at 2^refine times the cell size and every rank splits its triangles refine times (:mod:`fempm.meshes.refinement`; a large mesh made in parallel).
    """
    ppc = (16 if body == "disk" else 4) if ppc is None else ppc
    flip = (1.0 if body == "disk" else BLOCK_FLIP) if flip is None else flip
    gap = (0.5 if body == "disk" else 0.0) if gap is None else gap
    _check(body, angle, friction, plane, gap, cells, ppc)
    th = np.radians(angle)
    if t_end is None:
        t_end = max(float(np.sqrt(2.0 * 3.0 * size / (g * np.sin(th)))), 0.2)
    h = size / cells
    travel = 0.5 * g * np.sin(th) * t_end**2
    length = 2.0 * size
    x0 = 2.0 * h
    nx = int(np.ceil((x0 + length + 1.1 * travel + 2 * h) / h))
    ny = int(np.ceil(1.5 * (2.0 * size if body == "disk" else size) / h)) + 2
    below = 3 if plane == "rigid" else 0  # cells under the plane: the rigid layer and one empty row
    frame = np.array([[np.cos(th), np.sin(th)], [-np.sin(th), np.cos(th)]])  # columns: down the slope, normal
    corners = np.array([[0.0, 0.0], [nx * h, 0.0], [nx * h, ny * h], [0.0, ny * h]]) @ frame.T
    if refine and plane != "tagged":
        raise ValueError(f"refine={refine} refines the gmsh mesh: it needs plane='tagged'")
    if plane == "tagged":  # the slope's region turned by theta, its floor tagged
        data = tagged_polygon(comm, corners, h, [FLOOR_TAG, 0, 0, 0], refine=refine)
        mesh = data.mesh
    elif plane == "collider" and not turned:  # an axis-aligned grid over the turned region and a cell under it
        lo, hi = corners.min(axis=0) - h, corners.max(axis=0)
        n = np.ceil((hi - lo) / h).astype(int)
        mesh = dm.create_rectangle(comm, [lo, lo + n * h], n, dm.CellType.quadrilateral)
    elif plane == "collider":  # the slope's grid, turned by theta
        mesh = dm.create_rectangle(comm, [[0.0, 0.0], [nx * h, ny * h]], [nx, ny], dm.CellType.quadrilateral)
        mesh.geometry.x[:, :2] = mesh.geometry.x[:, :2] @ frame.T
    else:
        frame = np.eye(2)
        mesh = dm.create_rectangle(comm, [[0.0, -below * h], [nx * h, ny * h]], [nx, ny + below],
                                   dm.CellType.quadrilateral)
    p = _particles(mesh, body, plane, ppc, (x0, length, size, h), rho, g * np.cos(th), g * np.sin(th), nu, frame)
    track = _Track(frame[:, 0])

    def results(scene, solver) -> dict:
        return {"acceleration": slope_acceleration(track, scene.t_end),
                "analytic": analytic_acceleration(body, angle, friction, g)}

    params = {"body": body, "angle": angle, "friction": friction, "cells": cells, "ppc": ppc, "size": size, "E": E,
              "nu": nu, "rho": rho, "g": g, "scheme": scheme, "flip": flip, "mass": mass, "cfl": cfl, "plane": plane, "gap": gap,
              **({"turned": turned} if plane == "collider" else {}), **({"refine": refine} if refine else {})}

    def walls(V):
        if plane in ("rigid", "collider"):
            return []
        if plane == "tagged":
            return [tagged(V, data.facet_tags, FLOOR_TAG, "friction", friction)]
        return [friction_wall(V, lambda x: np.isclose(x[1], 0.0), (0.0, -1.0), friction,
                              gap=gap * h if gap > 0 else None)]

    colliders = [Collider(collider_plane((0.0, 0.0), frame[:, 1]), friction=friction,
                          gap=gap * h if gap > 0 else None)] if plane == "collider" else []
    return Scene(
        name="incline", mesh=mesh, particles=p, materials=[VonMises(E, nu)], t_end=t_end, bcs=walls,
        loads=Loads(body_force=(0.0, -g) if plane in ("tagged", "collider") else (g * np.sin(th), -g * np.cos(th))),
        colliders=colliders,
        options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl), frames=frames, params=params, results=results,
        watch=track, contact=Contact(friction=friction, field="plane", rigid=(1,), mass_cutoff=RIGID_MASS_CUTOFF,
                                     gap=(gap + _depth(ppc)) * h if gap > 0 else None) if plane == "rigid" else None,
    )


def _check(body: str, angle: float, friction: float, plane: str, gap: float, cells: int, ppc: int) -> None:
    """Refuse the options of :func:`incline` it cannot run, naming them."""
    if body not in BODIES:
        raise ValueError(f"unknown option body={body!r}; expected one of {', '.join(BODIES)}")
    check_counts(cells=cells, ppc=ppc)
    per_direction(ppc, 2)
    if not 0.0 < angle < 90.0:
        raise ValueError(f"angle={angle} must lie in (0, 90) degrees")
    if not 0.0 <= friction < np.inf:
        raise ValueError(f"friction={friction} must be >= 0")
    if plane not in PLANES:
        raise ValueError(f"unknown option plane={plane!r}; expected one of {', '.join(PLANES)}")
    if not 0.0 <= gap < np.inf:
        raise ValueError(f"gap={gap} must be >= 0 (cells)")
    if plane == "tagged" and (body != "block" or gap != 0.0):
        raise ValueError("plane='tagged' takes the block with gap=0 (a tagged wall holds every node moving into it)")


def _particles(mesh, body: str, plane: str, ppc: int, place: tuple[float, float, float, float], rho: float,
               g_normal: float, g_slope: float, nu: float, frame: np.ndarray):
    """The body's particles (group 0 of the field ``plane``; ``place``: its left end, length, size
    and the cell size) and, with ``plane="rigid"``, the rigid layer's (group 1). A block starts
    with the stress of a layer carrying its weight on the slope (plane strain). ``frame``: the
    slope's axes (columns) in the mesh's coordinates."""
    x0, length, size, h = place
    if body == "block":
        def inside(x):
            s, n = frame.T @ x[:2]
            return (s > x0) & (s < x0 + length) & (n > 0.0) & (n < size)
    else:
        def inside(x):
            s, n = frame.T @ x[:2]
            return np.hypot(s - x0 - size, n - size) < size
    p = create_particles(mesh, ppc, density=rho, where=inside if plane != "rigid" else
                         lambda x: inside(x) | ((x[1] < 0.0) & (x[1] > -2.0 * h)))
    normal = p.x[:, :2] @ frame[:, 1]
    group = (normal < 0.0).astype(np.int32)  # 0 the body, 1 the rigid plane (at rest)
    p.fields["plane"] = group
    if body == "block":  # at rest on the slope: the stress of a layer carrying its weight
        depth = np.where(group == 0, size - normal, 0.0)
        sigma = np.zeros((len(p), 2, 2))
        sigma[:, 1, 1] = -rho * g_normal * depth
        sigma[:, 0, 1] = sigma[:, 1, 0] = rho * g_slope * depth
        p.fields["sigma"] = frame @ sigma @ frame.T  # in the mesh's axes
        p.fields["sigma_zz"] = nu * sigma[:, 1, 1]  # plane strain
    return p
