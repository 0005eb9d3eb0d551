"""Vibrating bar (docs/verification.md), 1D or as a 2D strip."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fempm.boundary.walls import fixed
from fempm.materials.linear_elastic import LinearElastic
from fempm.meshes import structured as dm
from fempm.particles.seeding import create_particles, per_direction
from fempm.scene.definition import Scene, check_counts, checked
from fempm.scene.recorder import Recorder
from fempm.scenes.periods import crossing_period
from fempm.stepping.options import StepOptions

__all__ = ["CentreVelocity", "vibrating_bar"]


class CentreVelocity(Recorder):
    """The bar's centre-of-mass velocity along it after every step, ``points`` of (t, v_cm)
    (a scene ``watch``; checkpointed). Collective."""

    state_keys = ("points",)

    def __init__(self, particles, v):
        self.points = [(0.0, self.velocity(particles, v))]

    @staticmethod
    def velocity(particles, v) -> float:
        sums = particles.comm.allreduce(np.array([particles.mass @ v[:, 0], particles.mass.sum()]))
        return float(sums[0] / sums[1])

    def __call__(self, solver) -> None:
        p = solver.particles
        self.points.append((solver.t, self.velocity(p, p.fields["v"])))


@checked(positive=("L", "E", "rho"))
def vibrating_bar(
    *, cells: int = 16, ppc: int | None = None, scheme: str = "MUSL", flip: float = 1.0, mass: str = "lumped",
    cfl: float = 0.5, t_end: float = 40.0, L: float = 25.0, E: float = 100.0, rho: float = 1.0,
    v0: float = 0.1, mode: int = 1, dim: int = 1, lumped_forces: bool = False, comm: MPI.Comm = MPI.COMM_WORLD,
) -> Scene:
    """Bar fixed at x = 0, free at x = L, first mode: v(x, 0) = v0 sin(beta x); ``dim=2`` runs
    it as a 2D strip of one cell height (nu = 0: plane stress = plane strain = 1D).

    Exact: v_cm(t) = v0 / (beta L) cos(omega t), beta = (2 mode - 1) pi / (2 L), omega = beta c.
    The mesh extends 4 cells past the free end so the bar can stretch. Summary: ``period`` (from
    the crossings of zero by v_cm, :class:`CentreVelocity`), ``period_reference`` (2 pi / omega)
    and ``period_error`` (relative).

    Args:
        cells: Cells along the bar.
        ppc: Particles per cell, a lattice (None: 2 per direction).
        t_end: The end time (consistent units).
        L: The bar's length.
        E: Young's modulus (consistent units; nu = 0).
        rho: The density.
        v0: The velocity amplitude of the mode.
        mode: Which mode (1: the first).
        dim: 1 (intervals) or 2 (a strip one cell high).
    """
    check_counts(cells=cells, mode=mode, dim=dim)
    if dim not in (1, 2):
        raise ValueError(f"dim={dim} must be 1 or 2")
    ppc = 2**dim if ppc is None else ppc  # particles per cell: 2 per direction by default
    check_counts(ppc=ppc)
    per_direction(ppc, dim)
    h = L / cells
    if dim == 1:
        mesh = dm.create_interval(comm, cells + 4, [0.0, L + 4 * h])
    else:  # a strip one cell high (quadrilaterals), nu = 0: the same 1D solution
        mesh = dm.create_rectangle(comm, [[0.0, 0.0], [L + 4 * h, h]], [cells + 4, 1], dm.CellType.quadrilateral)
    p = create_particles(mesh, ppc, density=rho, cells=lambda x: x[0] < L)
    beta = (2 * mode - 1) * np.pi / (2 * L)
    p.fields["v"] = np.zeros((len(p), dim))
    p.fields["v"][:, 0] = v0 * np.sin(beta * p.x[:, 0])
    omega = beta * np.sqrt(E / rho)
    params = dict(cells=cells, ppc=ppc, scheme=scheme, flip=flip, mass=mass, cfl=cfl, L=L, E=E, rho=rho, v0=v0,
                  beta=beta, omega=omega, dim=dim)
    centre = CentreVelocity(p, p.fields["v"])

    def results(scene, solver) -> dict:
        period = crossing_period(*np.array(centre.points).T)
        return {"period": period, "period_reference": 2 * np.pi / omega, "period_error": period * omega / (2 * np.pi) - 1}

    return Scene(
        name="vibrating_bar", mesh=mesh, particles=p, materials=[LinearElastic(E, 0.0)], t_end=t_end,
        bcs=lambda V: [fixed(V, lambda x: np.isclose(x[0], 0.0))],
        options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl, lumped_forces=lumped_forces), params=params,
        watch=centre, results=results,
    )
