r"""Elastic compaction of a column under its own weight, in quasi-static implicit steps (the
verification problem of AMPLE, Coombs and Augarde 2020, and of Coombs et al. 2018).

A column of height :math:`l_0` = ``height`` and one cell's width stands on a fixed base between
rollers (slip walls normal to x), plane strain, linear elastic (``E``, ``nu`` = 0), density
:math:`\rho_0`; gravity :math:`g` is ramped from 0 to its value over the quasi-static steps
(``StepOptions(integrator="implicit", dynamics="quasi-static")``). Whatever the law, the
equilibrium of the part above a particle gives its vertical Cauchy stress from the particle's
initial height :math:`Y`,

.. math::
    \sigma_{yy}(Y) = -\rho_0 g\, (l_0 - Y)

(the rollers keep the column's width, so the weight above acts on the same area), and the
summary holds ``stress_error``, the relative, volume-weighted L2 error of the particles'
:math:`\sigma_{yy}` against it (:func:`stress_error`).
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fempm.boundary.walls import fixed, slip
from fempm.materials.linear_elastic import LinearElastic
from fempm.particles.seeding import create_particles, per_direction
from fempm.scene.definition import Scene, check_counts, checked
from fempm.scenes.dims import axis, block_mesh, check_dim, lattice_ppc
from fempm.stepping.loads import Loads
from fempm.stepping.options import StepOptions
from fempm.transfer.domains import step_domain

__all__ = ["compaction", "stress_error"]


@checked(positive=("height", "E", "rho"), non_negative=("g",))
def compaction(
    *, cells: int = 8, ppc: int | None = None, domain: str = "point", mass: str = "lumped", steps: int = 5, height: float = 50.0,
    E: float = 1.0e6, nu: float = 0.0, rho: float = 80.0, g: float = 10.0, t_end: float = 1.0, frames: int = 5,
    dim: int = 2, comm: MPI.Comm = MPI.COMM_WORLD,
) -> Scene:
    """The column with ``cells`` quadrilaterals over its height (one across), ``ppc`` particles a
    cell, loaded in ``steps`` quasi-static steps to ``t_end`` (a pseudo-time: gravity reaches its
    value there; see the module).

    Args:
        cells: Cells over the column's height.
        ppc: Particles per cell, a lattice (None: 4 in 2D, 8 in 3D).
        steps: The quasi-static load steps.
        height: The column's height in m.
        E: Young's modulus in Pa.
        nu: Poisson's ratio.
        rho: The density in kg/m^3.
        g: Gravity in m/s^2, reached at ``t_end``.
        t_end: The end of the load ramp (a pseudo-time).
        dim: 2 (plane strain) or 3 (a column of hexahedra, smooth walls all round).
    """
    dim = check_dim(dim)
    ppc = lattice_ppc(ppc, dim)
    check_counts(cells=cells, ppc=ppc, steps=steps)
    per_direction(ppc, dim)
    h = height / cells
    n = [1, cells + 1] + ([1] if dim == 3 else [])
    mesh = block_mesh(comm, [0.0] * dim, [h, height + h] + ([h] if dim == 3 else []), n)
    p = create_particles(mesh, ppc, density=rho, cells=lambda x: x[1] < height,
                         corners=step_domain(domain).tracks_corners)
    params = {"cells": cells, "ppc": ppc, "domain": domain, "mass": mass, "steps": steps, "height": height, "E": E,
              "nu": nu, "rho": rho, "g": g, "t_end": t_end, **({"dim": dim} if dim == 3 else {})}

    def bcs(V):
        sides = [slip(V, lambda x, k=k: np.isclose(x[k], 0.0) | np.isclose(x[k], h), axis(k, dim))
                 for k in ([0, 2] if dim == 3 else [0])]
        return [fixed(V, lambda x: np.isclose(x[1], 0.0)), *sides]

    return Scene(
        name="compaction", mesh=mesh, particles=p, materials=[LinearElastic(E, nu)], t_end=t_end, dt=t_end / steps,
        bcs=bcs, loads=Loads(body_force=axis(1, dim, -g)), frames=frames, params=params,
        options=StepOptions(integrator="implicit", dynamics="quasi-static", load_ramp=t_end, mass=mass, domain=domain),
        results=lambda scene, solver: {"stress_error": stress_error(solver.particles, height, rho, g)},
    )


def stress_error(particles, height: float, rho: float, g: float) -> float:
    r"""The relative, volume-weighted L2 error of the particles' :math:`\sigma_{yy}` against
    :math:`-\rho_0 g (l_0 - Y)`, with :math:`Y` the initial heights and the initial volumes as
    weights, over all ranks."""
    f = particles.fields
    exact = -rho * g * (height - f["X0"][:, 1])
    w = f["volume0"]
    sums = particles.comm.allreduce(np.array([float(w @ (f["sigma"][:, 1, 1] - exact) ** 2), float(w @ exact**2)]))
    return float(np.sqrt(sums[0] / sums[1]))
