r"""A pressure pulse in an elastic strip running into an absorbing or a fixed end.

The strip :math:`[0, L] \times [0, H]` (``rows`` cells high) is held between frictionless walls
at :math:`y = 0, H` and at :math:`x = 0` (uniaxial strain: a P wave of speed
:math:`c_p = \sqrt{(\lambda + 2\mu)/\rho}`). A pulse of particle velocity

.. math::
    v_x(x, 0) = a \cos^2\Big(\frac{\pi (x - x_0)}{2 w}\Big), \quad |x - x_0| < w,

with the stress of a wave running to the right, :math:`\sigma_{xx} = -\rho c_p v_x`
(:math:`F_{xx} = 1 - v_x / c_p`, :math:`\sigma_{yy} = \lambda \varepsilon_{xx}`), starts at
:math:`x_0 = 0.3 L` and meets the end :math:`x = L`: an absorbing boundary
(:func:`fempm.boundary.absorbing`, the dashpots of the strip's own :math:`\rho c_p, \rho c_s`)
or a fixed one (MUSL by default: USL's own dissipation takes 9 % of the pulse over its path
at 64 cells, MUSL's changes it by +0.6 %). The run ends when a reflected pulse would be back at :math:`x_0`,
:math:`t = 2 (L - x_0) / c_p`; then

``reflected_energy_ratio`` = (kinetic + strain energy in the strip) / (the pulse's energy at
the start): about 0 for a boundary that absorbs it, about 1 for one that reflects it (less the
scheme's own dissipation over the path).
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fempm.boundary.absorbing import absorbing
from fempm.boundary.walls import fixed, slip
from fempm.materials.linear_elastic import LinearElastic
from fempm.meshes import structured as dm
from fempm.particles.seeding import create_particles
from fempm.scene.definition import Scene, check_counts, check_finite, checked
from fempm.stepping import diagnostics
from fempm.stepping.options import StepOptions

__all__ = ["BOUNDARIES", "wave"]

#: the strip's right end
BOUNDARIES = ("absorbing", "fixed")

#: the pulse starts at this fraction of the length, with this half-width
START, HALF_WIDTH = 0.3, 0.1


@checked(positive=("E", "rho", "length", "amplitude"))
def wave(*, cells: int = 64, rows: int = 2, ppc: int = 4, boundary: str = "absorbing", E: float = 1.0, nu: float = 0.25,
         rho: float = 1.0, length: float = 1.0, amplitude: float = 1e-3, scheme: str = "MUSL", flip: float = 1.0,
         cfl: float = 0.5, frames: int = 0, mass: str = "lumped", comm: MPI.Comm = MPI.COMM_WORLD) -> Scene:
    """The pulse and its end (the module), ``cells`` along the strip.

    Args:
        cells: Cells along the strip.
        rows: Cells across the strip.
        ppc: Particles per cell, a lattice.
        boundary: The right end: "absorbing" or "fixed".
        E: Young's modulus (consistent units).
        nu: Poisson's ratio.
        rho: The density.
        length: The strip's length.
        amplitude: The pulse's velocity amplitude (below the wave speed).

    Raises:
        ValueError: An unknown ``boundary``, counts that are not positive, a pulse narrower
            than two cells, an amplitude that would invert the strip (:math:`a \\ge c_p`).
    """
    check_counts(cells=cells, rows=rows, ppc=ppc)
    check_finite(E=E, nu=nu, rho=rho, length=length, amplitude=amplitude)
    if boundary not in BOUNDARIES:
        raise ValueError(f"unknown boundary={boundary!r}; expected one of {', '.join(BOUNDARIES)}")
    h = length / cells
    if 2 * HALF_WIDTH * length < 2 * h:
        raise ValueError(f"cells={cells}: the pulse ({2 * HALF_WIDTH * length:g} wide) needs at least two cells")
    law = LinearElastic(E, nu)
    lam, mu = law.lame
    cp, cs = np.sqrt((lam + 2 * mu) / rho), np.sqrt(mu / rho)
    if not 0.0 < amplitude < cp:
        raise ValueError(f"amplitude={amplitude:g} must lie in (0, c_p = {cp:g})")
    height = rows * h
    mesh = dm.create_rectangle(comm, [[0.0, 0.0], [length, height]], [cells, rows], dm.CellType.quadrilateral)
    p = create_particles(mesh, ppc, density=rho)
    s = (p.x[:, 0] - START * length) / (HALF_WIDTH * length)
    vx = np.where(np.abs(s) < 1.0, amplitude * np.cos(0.5 * np.pi * s) ** 2, 0.0)
    p.fields["v"] = np.stack([vx, np.zeros_like(vx)], axis=1)
    F = np.tile(np.eye(2), (len(p), 1, 1))
    F[:, 0, 0] -= vx / cp  # a wave running to the right: eps_xx = -v_x / c_p
    p.fields["F"] = F
    p.fields["sigma"] = law.stress_numpy(F, None, None, 0.0, None)
    p.fields["body"] = np.zeros(len(p), dtype=np.int32)
    p.fields["volume0"] = p.volume.copy()  # the seeding's volumes are the reference ones
    p.volume *= np.linalg.det(F)
    energy0 = diagnostics.energies(p, [law], 0.0)["total"]

    def bcs(V):
        walls = [slip(V, lambda x: np.isclose(x[1], 0.0) | np.isclose(x[1], height), (0.0, 1.0)),
                 slip(V, lambda x: np.isclose(x[0], 0.0), (1.0, 0.0))]

        def end(x):
            return np.isclose(x[0], length)

        if boundary == "fixed":
            return [*walls, fixed(V, end)]
        return [*walls, absorbing(V, rho=rho, cp=cp, cs=cs, where=end)]

    def results(scene, solver) -> dict:
        return {"reflected_energy_ratio": solver.energies()["total"] / energy0, "pulse_energy": energy0}

    params = {"cells": cells, "rows": rows, "ppc": ppc, "boundary": boundary, "E": E, "nu": nu, "rho": rho,
              "length": length, "amplitude": amplitude, "scheme": scheme, "flip": flip, "mass": mass, "cfl": cfl, "cp": cp, "cs": cs}
    return Scene(name="wave", mesh=mesh, particles=p, materials=[law], t_end=2 * (1 - START) * length / cp, bcs=bcs,
                 options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl), frames=frames, params=params, results=results)
