r"""A block sliding or a disk rolling down a frictional incline (plane strain, elastic).

The incline is the grid boundary :math:`y = 0` with Coulomb friction ``friction`` :math:`\mu`
(:func:`fempm.boundary.friction`), or a rigid body in frictional contact (``plane="rigid"``),
in the frame of the slope: :math:`x` runs down it and gravity is
:math:`g (\sin\theta, -\cos\theta)` for the slope angle :math:`\theta` (``angle``, degrees),
which is the inclined plane itself, rotated. The body is elastic and objective under the
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

What rolling takes. With every node of the plane that the disk moves into held, the disk
meets the plane across the :math:`\sim\sqrt{8 R h}` of nodes its bottom cells touch, which
stops its rotation: it slid at mu = 0.3 (2.35 m/s^2 against the rolling 3.27). The plane
therefore holds only the nodes the body touches (its nodal centre of mass within ``gap``
cells, :class:`fempm.boundary.Friction`), and the disk has 4 x 4 particles per cell (with 2 x 2
its staircase of particles rolls with errors up to 4 % at 16 cells).

What sliding takes. The block slides on its flat face, and the sliding of an elastic body on a
Coulomb plane is unstable: the rocking of the block and the waves along its base grow (its
strain energy from 0.004 J to 0.2 J in 0.35 s at mu = 0.5), some nodes of the base move uphill
for a moment and the friction pushes them downhill, so the plane takes less friction than
mu times its normal impulse (0.454 instead of 0.5) and the block slides too fast (mu = 0.5,
FLIP 1: 1.25 m/s^2 against 0.657 at 8 cells, 3.06 at 16: worse on the finer grid, as an
ill-posed problem is; 1.07 and 1.39 at CFL 0.1 and 0.8, 3.16, 1.50 and 1.28 at 1, 9 and 16
particles per cell)
and creeps where it should stick (mu = 0.6: 0.90 m/s^2). Pure FLIP has nothing that damps it;
5 % of PIC (``flip=0.95``) brings mu = 0.5 to 0.2 % (8 cells) and 1.0 % (16); 20 % (0.8) held
the block at mu = 0.6 only just (0.041 m/s^2 at 8 cells against the limit 0.049 of 1 % of
g sin, 0.080 at 4 cells), 30 % (0.7) with a margin on either plane (0.028 and 0.019 m/s^2 at 8
and 16 cells on the grid plane, 0.031 and 0.020 on the rigid plane, 0 at 4 cells; mu = 0.5
within 0.5 %). The block's default is therefore ``flip=0.7``; the disk, whose rolling PIC would
brake (at FLIP 0.8 it rolled at 0.84 m/s^2 instead of 3.27 at mu = 1), keeps pure FLIP
(``flip=1.0``). Consistent mass damps less than lumped: a sticking block needs more PIC there
(docs/contact.md).

Measured (``python demos/incline.py``, 30 degrees, MUSL; docs/incline/incline.md and
docs/contact.md): every case within 2 % at 8 and 16 cells, on either plane, the disk within
0.84 % also just above its rolling threshold (mu = 0.2 and 0.22). That takes a plane that
shares its normal impulse over the nodes the disk touches (:class:`fempm.boundary.Friction`,
and :func:`fempm.stepping.contact.correct` for the rigid plane): held node by node, the node ahead of
the contact point carried the disk's weight, up to a cell ahead of its centre, and braked the
rotation, so that the disk slid at mu = 0.2 (-1.5 % and -2.0 %) and rolled only from
mu = 0.25-0.3 at 8 cells.

The results (:func:`slope_acceleration`): ``acceleration``, the along-slope acceleration of the
body's centre of mass once it moves (:math:`2 c_2` of the least-squares fit
:math:`x_c(t) = c_0 + c_1 t + c_2 t^2` over the second half of the run, after the body has
settled on the plane), and ``analytic``, the value above.
"""

from __future__ import annotations

import dolfinx.mesh as dm
import numpy as np
from mpi4py import MPI

from fempm.boundary.walls import friction as friction_wall
from fempm.materials.von_mises import VonMises
from fempm.particles.seeding import create_particles, per_direction
from fempm.scene.definition import Scene, check_counts
from fempm.stepping.contact import Contact
from fempm.stepping.loads import Loads
from fempm.stepping.options import StepOptions

__all__ = [
    "BLOCK_FLIP", "BODIES", "PLANES", "RIGID_MASS_CUTOFF", "analytic_acceleration", "incline",
    "slope_acceleration",
]

BODIES = ("block", "disk")
#: the PIC/FLIP blend of the block by default: pure FLIP lets the frictional sliding of the
#: elastic block go unstable (see the module)
BLOCK_FLIP = 0.7
PLANES = ("grid", "rigid")
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


class _Track:
    """The body's centre of mass along the slope after every step (a scene ``watch``)."""

    def __init__(self):
        self.t: list[float] = []
        self.x: list[float] = []

    def __call__(self, solver) -> None:
        p = solver.particles
        mass = np.where(p.fields["plane"] == 0, p.mass, 0.0)  # the body, not a rigid plane
        sums = np.array([mass @ p.x[:, 0], mass.sum()])
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


def incline(
    body: str = "block", angle: float = 30.0, friction: float = 0.2, cells: int = 8, ppc: int | None = None,
    size: float = 0.1, E: float = 1.0e6, nu: float = 0.3, rho: float = 1000.0, g: float = 9.81,
    t_end: float | None = None, scheme: str = "MUSL", flip: float | None = None, cfl: float = 0.4, frames: int = 10,
    plane: str = "grid", gap: float | None = None, comm: MPI.Comm = MPI.COMM_WORLD,
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
    nodal centre of mass, which lies :func:`_depth` cells under its surface)."""
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
    mesh = dm.create_rectangle(comm, [[0.0, -below * h], [nx * h, ny * h]], [nx, ny + below], dm.CellType.quadrilateral)
    p = _particles(mesh, body, plane, ppc, (x0, length, size, h), rho, g * np.cos(th), g * np.sin(th), nu)
    track = _Track()

    def results(scene, solver) -> dict:
        return {"acceleration": slope_acceleration(track, scene.t_end),
                "analytic": analytic_acceleration(body, angle, friction, g)}

    params = {"body": body, "angle": angle, "friction": friction, "cells": cells, "ppc": ppc, "size": size, "E": E,
              "nu": nu, "rho": rho, "g": g, "scheme": scheme, "flip": flip, "cfl": cfl, "plane": plane, "gap": gap}

    def walls(V):
        if plane == "rigid":
            return []
        return [friction_wall(V, lambda x: np.isclose(x[1], 0.0), (0.0, -1.0), friction,
                              gap=gap * h if gap > 0 else None)]

    return Scene(
        name="incline", mesh=mesh, particles=p, materials=[VonMises(E, nu)], t_end=t_end, bcs=walls,
        loads=Loads(body_force=(g * np.sin(th), -g * np.cos(th))),
        options=StepOptions(scheme=scheme, flip=flip, cfl=cfl), frames=frames, params=params, results=results,
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


def _particles(mesh, body: str, plane: str, ppc: int, place: tuple[float, float, float, float], rho: float,
               g_normal: float, g_slope: float, nu: float):
    """The body's particles (group 0 of the field ``plane``; ``place``: its left end, length, size
    and the cell size) and, with ``plane="rigid"``, the rigid layer's (group 1). A block starts
    with the stress of a layer carrying its weight on the slope (plane strain)."""
    x0, length, size, h = place
    if body == "block":
        def inside(x):
            return (x[0] > x0) & (x[0] < x0 + length) & (x[1] < size)
    else:
        def inside(x):
            return np.hypot(x[0] - x0 - size, x[1] - size) < size
    p = create_particles(mesh, ppc, density=rho, where=inside if plane == "grid" else
                         lambda x: inside(x) | ((x[1] < 0.0) & (x[1] > -2.0 * h)))
    group = (p.x[:, 1] < 0.0).astype(np.int32)  # 0 the body, 1 the rigid plane (at rest)
    p.fields["plane"] = group
    if body == "block":  # at rest on the slope: the stress of a layer carrying its weight
        depth = np.where(group == 0, size - p.x[:, 1], 0.0)
        sigma = np.zeros((len(p), 2, 2))
        sigma[:, 1, 1] = -rho * g_normal * depth
        sigma[:, 0, 1] = sigma[:, 1, 0] = rho * g_slope * depth
        p.fields["sigma"] = sigma
        p.fields["sigma_zz"] = nu * sigma[:, 1, 1]  # plane strain
    return p
