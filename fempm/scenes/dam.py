"""Dam break with Tait water (docs/verification.md) and Martin and Moyce's surge front."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fempm.boundary.walls import slip
from fempm.materials.newtonian_eos import NewtonianTait
from fempm.particles.seeding import create_particles, per_direction
from fempm.scene.definition import Scene, check_counts, checked
from fempm.scenes.dims import axis, block_mesh, check_dim, lattice_ppc
from fempm.stepping.health import Health
from fempm.stepping.loads import Loads
from fempm.stepping.options import StepOptions

__all__ = ["MARTIN_MOYCE", "dam_break", "surge_front"]

#: Martin and Moyce (1952), n^2 = 2: surge front Z = x / a against T = t sqrt(2 g / a)
#: (their Table 2, as tabulated in the dam-break literature).
MARTIN_MOYCE = np.array([
    [0.41, 1.11], [0.84, 1.22], [1.19, 1.44], [1.43, 1.67], [1.63, 1.89], [1.83, 2.11], [1.98, 2.33], [2.20, 2.56],
    [2.32, 2.78], [2.51, 3.00], [2.65, 3.22], [2.83, 3.44], [2.98, 3.67], [3.11, 3.89], [3.33, 4.11],
])


def surge_front(particles, params: dict) -> float:
    """Martin and Moyce's Z = x_front / a: the rightmost particle plus half a particle spacing,
    over all ranks (their T is ``t * params["time_scale"]``)."""
    front = particles.comm.allreduce(particles.x[:, 0].max(initial=-np.inf), op=MPI.MAX)
    return (front + params["spacing"] / 2) / params["a"]


@checked(positive=("a", "box", "rho0", "kappa", "gamma"), non_negative=("viscosity", "g"))
def dam_break(
    *, cells: int = 10, ppc: int | None = None, scheme: str = "MUSL", flip: float = 0.99, mass: str = "lumped",
    cfl: float = 0.4, t_end: float = 0.22, a: float = 0.1, box: float = 0.4, rho0: float = 1000.0,
    kappa: float = 2.0e4, gamma: float = 7.0, viscosity: float = 1.0e-3, g: float = 9.81, frames: int = 22,
    dim: int = 2, comm: MPI.Comm = MPI.COMM_WORLD,
) -> Scene:
    r"""Dam break (docs/verification.md): a water column ``a`` wide and ``2 a`` high
    (n^2 = 2) at the left of a box ``box`` wide, slip walls left, right and at the bottom, open
    top; Tait water :math:`p = \kappa((\rho/\rho_0)^\gamma - 1)`.

    ``cells`` cells across the column width (square cells), ``ppc`` particles per
    cell. The column starts at rest in hydrostatic equilibrium: the particle density is
    :math:`\rho = \rho_0 (1 + \rho_0 g (2a - y) / \kappa)^{1/\gamma}` and its stress
    :math:`-p I`. Reference: the surge front of Martin and Moyce (1952), ``MARTIN_MOYCE``.
    With ``dim=3`` the tank is a channel ``a`` deep in z between two more slip walls, the
    column filling its depth (y up; the same surge front), on hexahedra.

    Args:
        cells: Cells across the water column's width.
        ppc: Particles per cell, a lattice (None: 4 in 2D, 8 in 3D).
        t_end: The end time in s.
        a: The column's width in m (its height is 2 a).
        box: The tank's width in m.
        rho0: The water's reference density in kg/m^3.
        kappa: Tait's bulk coefficient in Pa.
        gamma: Tait's exponent.
        viscosity: The dynamic viscosity in Pa s.
        g: Gravity in m/s^2.
        dim: 2 (plane strain) or 3 (a channel a deep).
    """
    dim = check_dim(dim)
    ppc = lattice_ppc(ppc, dim)
    check_counts(cells=cells, ppc=ppc)
    h = a / cells
    nx, ny = int(round(box / h)), int(round(3 * a / h))
    n = [nx, ny] if dim == 2 else [nx, ny, cells]
    mesh = block_mesh(comm, [0.0] * dim, [k * h for k in n], n)
    H = 2 * a

    def density(x):
        return rho0 * (1 + rho0 * g * (H - x[:, 1]) / kappa) ** (1 / gamma)

    p = create_particles(mesh, ppc, density=density, cells=lambda x: (x[0] < a) & (x[1] < H))
    water = NewtonianTait(rho0=rho0, kappa=kappa, gamma=gamma, viscosity=viscosity)
    pressure = water.pressure(p.mass / p.volume)
    p.fields["sigma"] = -pressure[:, None, None] * np.eye(dim)
    params = dict(cells=cells, ppc=ppc, scheme=scheme, flip=flip, mass=mass, cfl=cfl, a=a, box=nx * h, rho0=rho0,
                  kappa=kappa, gamma=gamma, viscosity=viscosity, g=g, spacing=h / per_direction(ppc, dim), time_scale=np.sqrt(2 * g / a),
                  **({"dim": dim} if dim == 3 else {}))
    W = nx * h

    def bcs(V):
        walls = [slip(V, lambda x: np.isclose(x[0], 0.0) | np.isclose(x[0], W), axis(0, dim)),
                 slip(V, lambda x: np.isclose(x[1], 0.0), axis(1, dim))]
        return walls + ([slip(V, lambda x: np.isclose(x[2], 0.0) | np.isclose(x[2], cells * h), axis(2, dim))]
                        if dim == 3 else [])

    return Scene(
        name="dam_break", mesh=mesh, particles=p, materials=[water], t_end=t_end, frames=frames, bcs=bcs,
        loads=Loads(body_force=axis(1, dim, -g)), options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl),
        params=params,
        # the column starts compressed with F = I, so the Tait energy W(J) misses the initial compression
        # and the energy balance cannot be checked: J bounds and the step floor still apply
        health=Health(energy_tolerance=None),
    )
