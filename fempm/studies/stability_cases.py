r"""The cases of the stability catalogue (:mod:`fempm.studies.stability`): small scenes that
stress one thing each. Every builder takes ``quick`` (a smaller, shorter version for CI) and
returns a :class:`~fempm.scene.Scene` with the default transfer options; the study then runs it
with each option of :func:`options_for`.

* ``nu=0.49``, ``nu=0.499``, ``nu=0.4999``: the two colliding disks, near-incompressible
  (the dilatational wave speed grows as :math:`(1 - 2\nu)^{-1/2}`, the shear one does not);
* ``stiffness-contrast-1e6``, ``density-contrast-1e4``: a free 1D bar of two bodies in
  contact (two halves; Young's moduli or densities in that ratio), vibrating in its first mode;
* ``ppc=1``, ``ppc=1/2``: the disks with one particle per cell and one per two cells (each
  direction), which leaves cells empty inside the body;
* ``near-empty-cells``: a block whose last particle column lies :math:`10^{-4} h` past a grid
  line (tiny nodal masses at the nodes beyond), stretching and contracting;
* ``high-velocity``: the disks at 10 m/s, 8.6 times the dilatational wave speed;
* ``sliver-cells``: the disks on triangles where every other column of cells is a sliver of
  width :math:`h/20`, with particles seeded uniformly (not per cell);
* ``stretch-J=20``, ``compress-J=0.05``: a soft neo-Hookean block in homogeneous expansion
  (or contraction) :math:`v = a (x - x_c)` whose free motion reaches :math:`J = 20`
  (:math:`0.05`) at :math:`t_{end}`;
* ``cfl``: the disks at CFL numbers 0.1 ... 1.0 (the options);
* ``long-run``: a small 1D vibrating bar for :math:`10^5` steps (1000 quick);
* ``plastic-impact``: the disks as von Mises (J2) solids, yield stress 1/50 of Young's
  modulus, at 0.2 m/s (the elastic impact stress :math:`\rho c v \approx 0.23 E` is 12 times
  the yield stress): the energy goes into plastic work;
* ``column-collapse``: a granular column (:func:`fempm.scenes.column_collapse`, Drucker-Prager,
  aspect ratio 2, 8 cells across; 4 cells and half the time quick) collapsing under gravity
  onto a rough floor;
* ``contact-disks``: the disks with one velocity field per disk and frictionless contact
  (:class:`fempm.stepping.contact.Contact`);
* ``contact-impact``: a disk fired at 10 m/s (0.86 times the wave speed) onto a plate with
  contact (:func:`fempm.scenes.disk_impact`, 20 cells; 16 quick);
* ``contact-rolling``: a disk rolling down a 30 degree incline, a rigid plane in frictional
  contact (mu = 0.3; :func:`fempm.scenes.incline`, 8 cells across the radius; 4 and a tenth of
  the time quick).

Contact takes USL or MUSL (and every domain): its USF rows are aborted with the
ValueError that says so.
"""

from __future__ import annotations

from collections.abc import Callable

import dolfinx.mesh as dm
import numpy as np
from mpi4py import MPI

from fempm.materials.linear_elastic import LinearElastic
from fempm.materials.neo_hookean import NeoHookean
from fempm.materials.von_mises import VonMises
from fempm.particles.particle_set import Particles
from fempm.particles.seeding import create_particles
from fempm.scene.definition import Scene
from fempm.scenes.bar import vibrating_bar
from fempm.scenes.column import column_collapse
from fempm.scenes.disks import two_disks
from fempm.scenes.impact import disk_impact
from fempm.scenes.incline import incline

__all__ = [
    "CASES", "cfl_case", "column", "contact_disks", "contact_impact", "contact_rolling", "high_velocity",
    "homogeneous", "long_run", "near_empty_cells", "nearly_incompressible", "plastic_impact", "sliver_cells",
    "sliver_mesh", "sparse_disks", "two_body_bar",
]


def _disks(quick: bool, comm, **kw) -> Scene:
    kw = {"cells": 10 if quick else 20, "t_end": 2.5 if quick else 3.0, **kw}
    return two_disks(frames=0, comm=comm, **kw)


def _transplant(scene: Scene, mesh: dm.Mesh) -> Scene:
    """The scene's particles (positions, mass, volume, fields) on another mesh."""
    p = scene.particles
    scene.particles = Particles(mesh, p.x, p.mass, p.volume, fields=dict(p.fields))
    scene.mesh = mesh
    return scene


def nearly_incompressible(nu: float) -> Callable:
    def build(quick: bool, comm=MPI.COMM_WORLD) -> Scene:
        return _disks(quick, comm, nu=nu)
    return build


def two_body_bar(E1: float, rho1: float) -> Callable:
    def build(quick: bool, comm=MPI.COMM_WORLD) -> Scene:
        r"""Free bar :math:`[0, 1]` (E = 1, rho = 1 for x < 1/2; E1, rho1 beyond) on
        :math:`[-1/4, 5/4]`, :math:`v = 0.01 \cos(\pi x)` less its mean (no drift); the run lasts ~1500 (10000) steps."""
        cells = 24 if quick else 48
        h = 1.5 / cells
        mesh = dm.create_interval(comm, cells, [-0.25, 1.25])
        p = create_particles(mesh, 2, density=lambda x: np.where(x[:, 0] < 0.5, 1.0, rho1), cells=lambda x: (x[0] > 0) & (x[0] < 1))
        p.fields["body"] = (p.x[:, 0] >= 0.5).astype(np.int32)
        v = 0.01 * np.cos(np.pi * p.x)
        p.fields["v"] = v - comm.allreduce(p.mass @ v) / comm.allreduce(p.mass.sum())  # no drift
        c_max = max(1.0, np.sqrt(E1 / rho1))
        t_end = (1500 if quick else 10000) * 0.4 * h / c_max
        return Scene(name="two_body_bar", mesh=mesh, particles=p, materials=[LinearElastic(1.0), LinearElastic(E1)],
                     t_end=t_end, frames=0, params=dict(E1=E1, rho1=rho1))
    return build


def sparse_disks(per_cell: float) -> Callable:
    def build(quick: bool, comm=MPI.COMM_WORLD) -> Scene:
        """The disks with ``per_cell`` particles per cell and direction (1 or 1/2): seeded one
        per cell on a mesh ``1/per_cell`` times coarser, run on the scene's mesh."""
        cells = 10 if quick else 20
        scene = _disks(quick, comm, cells=int(round(cells * per_cell)), ppc=1)
        if per_cell != 1:
            scene = _transplant(scene, dm.create_unit_square(comm, cells, cells, dm.CellType.quadrilateral))
        return scene
    return build


def near_empty_cells(quick: bool, comm=MPI.COMM_WORLD) -> Scene:
    r"""A block of 2x2 particles per cell over :math:`[1/4, 3/4]^2`, shifted so that its last
    column lies :math:`10^{-4} h` past the grid line :math:`x = 3/4`, with
    :math:`v_x = 0.1 (x - 1/2)`: the nodes beyond the line carry :math:`10^{-4}` of a normal
    nodal mass."""
    cells = 16
    h = 1.0 / cells
    mesh = dm.create_unit_square(comm, cells, cells, dm.CellType.quadrilateral)
    p = create_particles(mesh, 4, density=1000.0, cells=lambda x: (abs(x[0] - 0.5) < 0.25) & (abs(x[1] - 0.5) < 0.25))
    x = p.x.copy()
    x[:, 0] += 0.25 * h + 1e-4 * h
    v = np.zeros_like(x)
    v[:, 0] = 0.1 * (x[:, 0] - 0.5)
    p = Particles(mesh, x, p.mass, p.volume, fields={"v": v})
    return Scene(name="near_empty_cells", mesh=mesh, particles=p, materials=[LinearElastic(1000.0, 0.3)],
                 t_end=1.0 if quick else 3.0, frames=0)


def high_velocity(quick: bool, comm=MPI.COMM_WORLD) -> Scene:
    scene = _disks(quick, comm, speed=10.0)
    scene.t_end = 0.05
    return scene


def sliver_mesh(cells: int, comm) -> dm.Mesh:
    """Structured triangles on the unit square with every odd interior vertex column moved by
    0.95 h: every other column of cells is a sliver of width h/20."""
    mesh = dm.create_unit_square(comm, cells, cells)
    x = mesh.geometry.x
    h = 1.0 / cells
    col = np.rint(x[:, 0] / h).astype(int)
    odd = (col % 2 == 1) & (col < cells)
    x[odd, 0] += 0.95 * h
    return mesh


def sliver_cells(quick: bool, comm=MPI.COMM_WORLD) -> Scene:
    cells = 10 if quick else 20
    return _transplant(_disks(quick, comm), sliver_mesh(cells, comm))


def homogeneous(J_end: float) -> Callable:
    def build(quick: bool, comm=MPI.COMM_WORLD) -> Scene:
        r"""A soft neo-Hookean block (E = 0.01, nu = 0.3, rho = 1) with
        :math:`v = a (x - x_c)`, :math:`(1 + a)^2 = J_{end}` over :math:`t_{end} = 1`: free
        homogeneous expansion (a block of half-width 0.1) or contraction (half-width 0.4)."""
        cells = 16 if quick else 32
        half = 0.1 if J_end > 1 else 0.4
        mesh = dm.create_unit_square(comm, cells, cells, dm.CellType.quadrilateral)
        p = create_particles(mesh, 4, density=1.0, where=lambda x: (abs(x[0] - 0.5) < half) & (abs(x[1] - 0.5) < half))
        a = np.sqrt(J_end) - 1.0
        p.fields["v"] = a * (p.x - 0.5)
        return Scene(name="homogeneous", mesh=mesh, particles=p, materials=[NeoHookean(0.01, 0.3)], t_end=1.0,
                     frames=0, params=dict(J_end=J_end))
    return build


def cfl_case(quick: bool, comm=MPI.COMM_WORLD) -> Scene:
    return _disks(quick, comm)


def long_run(quick: bool, comm=MPI.COMM_WORLD) -> Scene:
    """The vibrating bar on 8 cells with a fixed step: 1e5 steps (1000 quick)."""
    scene = vibrating_bar(cells=8, comm=comm)
    steps = 1_000 if quick else 100_000
    c = np.sqrt(scene.params["E"] / scene.params["rho"])
    scene.dt = 0.4 * (scene.params["L"] / 8) / (c + scene.params["v0"])
    scene.t_end = steps * scene.dt
    scene.frames = 0
    return scene


def plastic_impact(quick: bool, comm=MPI.COMM_WORLD) -> Scene:
    """The disks (E = 1000, nu = 0.3, rho = 1000) as von Mises solids with yield stress 20, at
    0.2 m/s, until after they have come to rest against each other."""
    scene = _disks(quick, comm, speed=0.2)
    scene.materials = [VonMises(1000.0, 0.3, yield_stress=20.0)]
    scene.t_end = 1.6  # 0.8 s after contact: before the splash along the contact line reaches the walls
    return scene


def column(quick: bool, comm=MPI.COMM_WORLD) -> Scene:
    """The granular column of aspect ratio 2 on 8 cells across (4 quick), for the time of
    its collapse (half of it quick)."""
    scene = column_collapse(aspect=2.0, cells=4 if quick else 8, frames=0, comm=comm)
    scene.t_end *= 0.25 if quick else 0.5
    return scene


def contact_disks(quick: bool, comm=MPI.COMM_WORLD) -> Scene:
    """The disks with contact (one field per disk, no friction)."""
    return _disks(quick, comm, contact=True)


def contact_impact(quick: bool, comm=MPI.COMM_WORLD) -> Scene:
    """The disk onto the plate at 10 m/s with contact, 20 cells (16 quick)."""
    return disk_impact(cells=16 if quick else 20, frames=0, comm=comm)


def contact_rolling(quick: bool, comm=MPI.COMM_WORLD) -> Scene:
    """The disk rolling down a rigid plane at 30 degrees, mu = 0.3, 8 cells across the radius
    with 4 x 4 particles per cell (quick: 4 cells, 2 x 2 particles, a tenth of the time)."""
    scene = incline("disk", 30.0, 0.3, cells=4 if quick else 8, ppc=4 if quick else 16, plane="rigid", frames=0,
                    comm=comm)
    if quick:
        scene.t_end *= 0.1
    return scene


CASES: dict[str, Callable] = {
    "nu=0.49": nearly_incompressible(0.49),
    "nu=0.499": nearly_incompressible(0.499),
    "nu=0.4999": nearly_incompressible(0.4999),
    "stiffness-contrast-1e6": two_body_bar(1e6, 1.0),
    "density-contrast-1e4": two_body_bar(1.0, 1e4),
    "ppc=1": sparse_disks(1.0),
    "ppc=1/2": sparse_disks(0.5),
    "near-empty-cells": near_empty_cells,
    "high-velocity": high_velocity,
    "sliver-cells": sliver_cells,
    "stretch-J=20": homogeneous(20.0),
    "compress-J=0.05": homogeneous(0.05),
    "cfl": cfl_case,
    "long-run": long_run,
    "plastic-impact": plastic_impact,
    "column-collapse": column,
    "contact-disks": contact_disks,
    "contact-impact": contact_impact,
    "contact-rolling": contact_rolling,
}
