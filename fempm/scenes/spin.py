r"""A free elastic disk spinning about its centre: the velocity transfers' angular momentum and
kinetic energy (docs/transfers.md).

The disk, of radius ``radius`` about the centre of the unit square, starts in the rigid
rotation :math:`v = \omega \times (x - c)` (its velocity gradient given to APIC and TPIC:
:attr:`fempm.scene.Scene.velocity_gradient`), with no load and no wall. The exact motion keeps
the angular momentum and, up to the small elastic stretch the rotation causes (strain energy
of order :math:`(\omega R / c_p)^2` of the kinetic), the kinetic energy. Summary:
``angular_momentum_drift`` (the largest :math:`|L(t) - L(0)| / |L(0)|` over the run, with the
affine part the map carries: :meth:`fempm.stepping.Solver.angular_momentum`) and
``kinetic_ratio`` (the final kinetic energy over the initial).

The step keeps every conservation the transfers can give: the particles move with their own
velocity (``position="particle"``: with MUSL the re-mapped grid velocity would move them
otherwise than their momenta say), every node with mass takes its force (``mass_cutoff=0`` by
default) and the consistent mass lumps no row (``lump_below=0``), so APIC keeps the angular
momentum to round-off with the lumped and the consistent mass. What that costs (docs/transfers.md):
a node at the rim, supported by one particle with a tiny share of its mass, takes an
acceleration that the velocity gradient, hence APIC's and TPIC's affine matrices, would carry
back (the transfers' ``affine_cutoff``, 1e-2 by default, weighs it by the node's mass, and APIC
still keeps the angular momentum to round-off, 10 to 60 cells); the consistent mass without
lumped rows grows unstable at the rim within a few hundred steps; structured triangles need
``cfl=0.2`` with APIC.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fempm.materials.neo_hookean import NeoHookean
from fempm.meshes import structured as dm
from fempm.meshes.generators import MESHES, read_msh
from fempm.particles.seeding import create_particles
from fempm.scene.definition import Scene, check_counts, checked
from fempm.scene.recorder import Recorder
from fempm.stepping.diagnostics import totals
from fempm.stepping.options import StepOptions

__all__ = ["SpinHistory", "spin"]

#: the disk's centre
CENTRE = np.array([0.5, 0.5])


class SpinHistory(Recorder):
    """The angular momentum and kinetic energy after every step, ``points`` of (t, L, K) (a scene
    ``watch``; checkpointed). Collective."""

    state_keys = ("points",)

    def __init__(self):
        self.points: list = []

    @staticmethod
    def point(solver) -> tuple[float, float, float]:
        return solver.t, solver.angular_momentum()["angular_momentum"], float(totals(solver.particles,
                                                                                     solver.materials)[1])

    def start(self, solver) -> None:
        self.points = [self.point(solver)]

    def __call__(self, solver) -> None:
        self.points.append(self.point(solver))


@checked(positive=("E", "rho", "radius", "t_end"), non_negative=("omega",))
def spin(
    *, mesh: str = "quadrilateral", cells: int = 20, ppc: int = 4, scheme: str = "MUSL", flip: float = 1.0,
    mass: str = "lumped", cfl: float = 0.4, t_end: float = 1.0, omega: float = 2 * np.pi, radius: float = 0.3,
    E: float = 1000.0, nu: float = 0.3, rho: float = 1.0, mass_cutoff: float = 0.0, frames: int = 10,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> Scene:
    """A neo-Hookean disk spinning at ``omega`` about the centre of the unit square, plane strain.

    Args:
        mesh: quadrilateral or triangle (structured, ``cells`` per side), or unstructured (the
            triangles of meshes/unit_square_tri.msh).
        cells: Cells along each side of the unit square.
        ppc: Particles per cell, a lattice.
        t_end: The end time (1: one turn at the default ``omega``).
        omega: The angular velocity (rad per unit time).
        radius: The disk's radius, at most 0.45.
        E: Young's modulus.
        nu: Poisson's ratio.
        rho: The density.
        mass_cutoff: Nodes whose mass is below this share of the largest take no force update
            (:class:`fempm.stepping.StepOptions`; 0: every node takes its force, the angular
            momentum kept to round-off).
    """
    check_counts(cells=cells, ppc=ppc)
    if not radius <= 0.45:
        raise ValueError(f"radius={radius} must be at most 0.45: the spinning disk must stay inside the unit square")
    if mesh in ("quadrilateral", "triangle"):
        m = dm.create_unit_square(comm, cells, cells, getattr(dm.CellType, mesh))
    elif mesh == "unstructured":
        m = read_msh(MESHES / "unit_square_tri.msh", comm, gdim=2).mesh
    else:
        raise ValueError(f"unknown option mesh={mesh!r}; expected quadrilateral, triangle or unstructured")
    p = create_particles(m, ppc, density=rho, where=lambda x: np.hypot(x[0] - CENTRE[0], x[1] - CENTRE[1]) < radius)
    W = np.array([[0.0, -omega], [omega, 0.0]])
    p.fields["v"] = (p.x - CENTRE) @ W.T
    history = SpinHistory()
    params = dict(mesh=mesh, cells=cells, ppc=ppc, scheme=scheme, flip=flip, mass=mass, cfl=cfl, omega=omega,
                  radius=radius, E=E, nu=nu, rho=rho, mass_cutoff=mass_cutoff)

    def results(scene, solver) -> dict:
        t, L, K = np.array(history.points).T
        return {"angular_momentum_drift": float(np.max(np.abs(L - L[0])) / abs(L[0])) if L[0] else 0.0,
                "kinetic_ratio": float(K[-1] / K[0]) if K[0] else 1.0}

    return Scene(
        name="spin", mesh=m, particles=p, materials=[NeoHookean(E, nu)], t_end=t_end, frames=frames,
        options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl, position="particle",
                            mass_cutoff=mass_cutoff, lump_below=0.0), params=params, watch=history,
        results=results, velocity_gradient=W,
    )
