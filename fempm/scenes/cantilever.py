"""Cantilever under self-weight (docs/verification.md) and its beam-theory reference."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fempm.boundary.walls import fixed
from fempm.materials.linear_elastic import LinearElastic
from fempm.materials.neo_hookean import NeoHookean
from fempm.meshes import structured as dm
from fempm.particles.seeding import create_particles, per_direction
from fempm.scene.definition import Scene, check_counts, check_finite, checked, dofs_per_cell
from fempm.stepping.loads import Loads
from fempm.stepping.options import StepOptions
from fempm.transfer.domains import step_domain
from fempm.transfer.mass_models import mass_model

__all__ = ["cantilever", "cantilever_reference", "cantilever_tip"]


def cantilever_reference(L: float = 0.7, H: float = 0.047, E: float = 6e7, rho: float = 1000.0,
                         g: float = 10.0) -> dict[str, float]:
    r"""Euler-Bernoulli tip deflection :math:`q L^4 / (8 E I)` (q = rho g H, I = H^3 / 12) and
    first-mode period :math:`2\pi / (1.8751^2 \sqrt{E I / (\rho H L^4)})` of a clamped beam of
    unit depth."""
    EI = E * H**3 / 12
    return {"tip_deflection": rho * g * H * L**4 / (8 * EI),
            "period": 2 * np.pi / (1.875104**2 * np.sqrt(EI / (rho * H * L**4)))}


def cantilever_tip(particles, params: dict) -> tuple[float, float]:
    """Mean initial x and mean downward deflection of the particles seeded in the beam's last
    cell column (``X0[:, 0] > L - hx``), over all ranks."""
    X0 = particles.fields["X0"]
    tip = X0[:, 0] > params["L"] - params["hx"]
    n, x, w = particles.comm.allreduce(np.array([tip.sum(), X0[tip, 0].sum(), np.sum(X0[tip, 1] - particles.x[tip, 1])]))
    return x / n, w / n


@checked(positive=("L", "H", "E", "rho"), non_negative=("g", "mass_cutoff"))
def cantilever(
    *, cells: int = 4, ppc: int | None = None, scheme: str = "MUSL", flip: float = 0.95, mass: str = "lumped",
    cfl: float = 0.4, t_end: float = 0.6, L: float = 0.7, H: float = 0.047, E: float = 6e7, nu: float = 0.0,
    rho: float = 1000.0, g: float = 10.0, material: str = "neo-hookean", degree: int = 1, mass_cutoff: float = 1e-9,
    domain: str = "point", frames: int = 20,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> Scene:
    r"""Cantilever under suddenly applied self-weight (docs/verification.md).

    Beam :math:`[0, L] \times [0, H]`, clamped at x = 0 (all grid velocities zero at x <= 0; the
    mesh has one cell column behind the clamp), ``cells`` cells through the thickness (cells as close to square as
    fits L), plane strain
    (nu = 0 makes it plane stress as well). Euler-Bernoulli static tip deflection
    :math:`\delta = q L^4 / (8 E I)`, q = rho g H, I = H^3 / 12; with no damping the tip
    oscillates about it (period :math:`2\pi / (1.875^2 \sqrt{EI / (\rho H L^4)})`).
    Particles carry their initial position in ``fields["X0"]``.

    ``material``: "neo-hookean" (default; objective, so the beam's rotation, up to 0.1 rad at the
    tip, makes no stress) or "linear" (small strain :math:`\mathrm{sym}\,F - I`, which a
    rotation by :math:`\theta` strains by :math:`\cos\theta - 1`: about 25 % of the bending
    strain near the tip here).

    ``ppc``: particles per cell, a square lattice (default :math:`(k + 1)^2` for degree
    :math:`k`: 4, and 9 for P2, which a consistent mass needs at least).

    Args:
        cells: Cells through the beam's thickness.
        ppc: Particles per cell, a lattice (None: (degree + 1)^2).
        t_end: The end time in s.
        L: The beam's length in m.
        H: The beam's thickness in m.
        E: Young's modulus in Pa.
        nu: Poisson's ratio.
        rho: The density in kg/m^3.
        g: Gravity in m/s^2.
        material: "neo-hookean" or "linear" (small strain).
        degree: The velocity space's degree (1 or 2).
    """
    ppc = (degree + 1) ** 2 if ppc is None else ppc
    check_counts(cells=cells, ppc=ppc, degree=degree)
    check_finite(t_end=t_end, L=L, H=H, E=E, nu=nu, rho=rho, g=g)
    per_direction(ppc, 2)
    if mass_model(mass).matrix and ppc < dofs_per_cell("quadrilateral", degree):
        raise ValueError(f"ppc={ppc} particles per cell cannot determine the consistent mass of degree {degree} "
                         f"({dofs_per_cell('quadrilateral', degree)} dofs per quadrilateral): give ppc="
                         f"{(degree + 1) ** 2} or more, or leave it unset")
    if material not in ("neo-hookean", "linear"):
        raise ValueError(f"unknown option material={material!r}; expected neo-hookean or linear")
    hy = H / cells
    nl = max(int(round(L / hy)), 1)
    hx = L / nl
    tip = cantilever_reference(L, H, E, rho, g)["tip_deflection"]
    below = int(np.ceil(3 * tip / hy)) + 2  # room below the beam for the swing (twice the deflection)
    # one cell column behind the clamp, so that particle domains (GIMP, CPDI) at the clamp stay in the mesh
    mesh = dm.create_rectangle(comm, [[-hx, -below * hy], [(nl + 2) * hx, H + 2 * hy]], [nl + 3, below + cells + 2],
                               dm.CellType.quadrilateral)
    p = create_particles(mesh, ppc, density=rho, cells=lambda x: (x[0] > 0) & (x[0] < L) & (x[1] > 0) & (x[1] < H),
                         corners=step_domain(domain).tracks_corners)  # CPDI2: each particle is its sub-cell
    p.fields["X0"] = p.x.copy()
    params = dict(cells=cells, ppc=ppc, scheme=scheme, flip=flip, mass=mass, cfl=cfl, L=L, H=H, E=E, nu=nu, rho=rho,
                  g=g, hx=hx, material=material, degree=degree, mass_cutoff=mass_cutoff, domain=domain, **cantilever_reference(L, H, E, rho, g))
    return Scene(
        name="cantilever", mesh=mesh, particles=p,
        materials=[NeoHookean(E, nu) if material == "neo-hookean" else LinearElastic(E, nu)], t_end=t_end, frames=frames,
        bcs=lambda V: [fixed(V, lambda x: x[0] < 1e-9 * L)], loads=Loads(body_force=(0.0, -g)),
        options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl, mass_cutoff=mass_cutoff, domain=domain), degree=degree,
        params=params,
    )
