r"""A disk fired onto a plate at high speed: interpenetration with one grid velocity field, none
with contact (plane strain, neo-Hookean).

An elastic disk of radius :math:`R` (``radius``) moves down at ``speed`` onto a plate
:math:`[0.1, 0.9] \times [0, 0.2]` lying on a smooth floor :math:`y = 0` of the unit-wide
domain, both neo-Hookean (``E``, ``nu``, ``rho``; the defaults give a dilatational wave speed
of 11.6 m/s, and the default 10 m/s is 0.86 times it). With one velocity field the two bodies
share the nodes between them and stick; at this speed the particles at the interface are
crushed (at 20 cells the run stops with :math:`J \le 0` as the disk pulls back). With
``contact`` (:class:`fempm.stepping.contact.Contact`, one field per body, Coulomb ``friction``,
contact only where the bodies touch: ``gap`` cells between their nodal centres of mass) the
disk stops on the plate's surface and rebounds: at 20 cells the columns of particles under
its middle stay 0.67 particle spacings apart at the closest, :math:`J \ge 0.5`, it leaves at
4.9 m/s and no cell holds both bodies at the end; at 40 cells (the default) 0.18 spacings
apart and 5.1 m/s. The scene's scheme is USL, not the library's MUSL: with contact fields MUSL
gains energy (17-18 % on the colliding disks; here it keeps 0.93 of it against USL's 0.61,
docs/contact.md).

The results (:class:`_Overlap`): ``penetration``, the deepest interpenetration over the run in
particle spacings, :math:`\max_t \max_b (y^{plate}_{top,b} - y^{disk}_{bottom,b}) / s` over
columns :math:`b` of one particle spacing :math:`s` under the disk's middle,
:math:`|x - 0.5| < R/4` (negative: the bodies stayed apart), and
``rebound``, the disk's centre-of-mass velocity along :math:`y` at the end (positive: it
bounced back), and ``shared_cells``, the number of cells holding particles of both bodies at
the end.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fempm.boundary.walls import slip
from fempm.materials.neo_hookean import NeoHookean
from fempm.meshes import structured as dm
from fempm.particles.seeding import create_particles, per_direction
from fempm.scene.definition import Scene, check_counts, checked
from fempm.scene.recorder import Recorder
from fempm.stepping.contact import Contact, shared_cells
from fempm.stepping.options import StepOptions

__all__ = ["PLATE", "disk_impact"]

PLATE = (0.1, 0.9, 0.2)  # x from, x to, thickness


class _Overlap(Recorder):
    """The deepest interpenetration of the disk (``fields["impactor"]`` 1) into the plate (0)
    after every step (a scene ``watch``), in columns of width ``spacing`` over
    :math:`|x - 0.5| <` ``half`` (under the disk's middle, where the plate cannot wrap around
    its sides and the interface is nearly level). Checkpointed."""

    state_keys = ("deepest",)

    def __init__(self, spacing: float, half: float):
        self.spacing = spacing
        self.x0 = 0.5 - half
        self.bins = max(int(np.ceil(2.0 * half / spacing)), 1)
        self.deepest = -np.inf

    def __call__(self, solver) -> None:
        p = solver.particles
        b = np.floor((p.x[:, 0] - self.x0) / self.spacing).astype(np.int64)
        inside = (b >= 0) & (b < self.bins)
        b = np.where(inside, b, 0)
        disk = (p.fields["impactor"] == 1) & inside
        plate = (p.fields["impactor"] == 0) & inside
        top = np.full(self.bins, -np.inf)
        np.maximum.at(top, b[plate], p.x[plate, 1])
        bottom = np.full(self.bins, -np.inf)
        np.maximum.at(bottom, b[disk], -p.x[disk, 1])
        p.comm.Allreduce(MPI.IN_PLACE, top, op=MPI.MAX)
        p.comm.Allreduce(MPI.IN_PLACE, bottom, op=MPI.MAX)
        both = np.isfinite(top) & np.isfinite(bottom)
        if both.any():
            self.deepest = max(self.deepest, float((top[both] + bottom[both]).max()) / self.spacing)


@checked(positive=("radius", "E", "rho"), non_negative=("gap", "speed", "friction"))
def disk_impact(
    *, cells: int = 40, ppc: int = 4, speed: float = 10.0, radius: float = 0.1, E: float = 1.0e5, nu: float = 0.3,
    rho: float = 1000.0, contact: bool = True, friction: float = 0.0, gap: float = 0.8, scheme: str = "USL",
    flip: float = 1.0, cfl: float = 0.4, t_end: float = 0.08, frames: int = 10, mass: str = "lumped", comm: MPI.Comm = MPI.COMM_WORLD,
) -> Scene:
    """The impact of the module on a grid of ``cells`` x ``0.6 cells`` quadrilaterals over
    :math:`[0, 1] \\times [0, 0.6]`, ``ppc`` particles per cell (a square lattice); the disk starts two
    cells above the plate. ``gap``: the contact's position check in cells (0: none).

    Args:
        cells: Cells across the unit width.
        ppc: Particles per cell, a lattice.
        speed: The disk's speed in m/s.
        radius: The disk's radius in m.
        E: Young's modulus in Pa.
        nu: Poisson's ratio.
        rho: The density in kg/m^3.
        contact: One velocity field per body with contact (else one field).
        friction: The contact's Coulomb coefficient.
        gap: The contact's position check in cells (0: none).
        t_end: The end time in s.
    """
    check_counts(cells=cells, ppc=ppc)
    if friction and not contact:
        raise ValueError(f"friction={friction} needs contact=True: without contact the disk and the plate share one "
                         "grid velocity and no friction acts between them")
    if not speed > 0.0:
        raise ValueError(f"speed={speed} must be > 0")
    if not 0.0 <= gap < np.inf:
        raise ValueError(f"gap={gap} must be >= 0 (cells)")
    h = 1.0 / cells
    ny = int(np.ceil(0.6 * cells))
    mesh = dm.create_rectangle(comm, [[0.0, 0.0], [1.0, ny * h]], [cells, ny], dm.CellType.quadrilateral)
    x0, x1, thick = PLATE
    centre = np.array([0.5, thick + 2.0 * h + radius])
    if not 0.0 < radius < min(0.5, (ny * h - centre[1] + radius) / 2):
        raise ValueError(f"radius={radius} must be > 0 and let the disk, two cells above the plate, fit in the "
                         f"{1.0:g} x {ny * h:g} mesh (radius < {min(0.5, (ny * h - centre[1] + radius) / 2):.3g})")

    def inside(x):
        plate = (x[0] > x0) & (x[0] < x1) & (x[1] < thick)
        return plate | (np.hypot(x[0] - centre[0], x[1] - centre[1]) < radius)

    p = create_particles(mesh, ppc, density=rho, where=inside)
    disk = (p.x[:, 1] > thick).astype(np.int32)
    p.fields["impactor"] = disk
    p.fields["v"] = np.outer(disk, [0.0, -speed])
    overlap = _Overlap(h / per_direction(ppc, 2), 0.25 * radius)

    def results(scene, solver) -> dict:
        k = p.fields["impactor"] == 1
        sums = np.array([p.mass[k] @ p.fields["v"][k, 1], p.mass[k].sum()])
        p.comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
        return {"penetration": overlap.deepest, "rebound": float(sums[0] / sums[1]),
                "shared_cells": shared_cells(p, "impactor")}

    params = dict(cells=cells, ppc=ppc, speed=speed, radius=radius, E=E, nu=nu, rho=rho, contact=contact,
                  friction=friction, gap=gap, scheme=scheme, flip=flip, mass=mass, cfl=cfl)
    return Scene(
        name="impact", mesh=mesh, particles=p, materials=[NeoHookean(E, nu)], t_end=t_end, frames=frames,
        bcs=lambda V: [slip(V, lambda x: np.isclose(x[1], 0.0), (0.0, -1.0))],
        options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl), params=params, results=results, watch=overlap,
        contact=Contact(friction=friction, field="impactor", gap=gap * h or None) if contact else None,
    )
