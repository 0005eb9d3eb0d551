r"""Granular column collapse: a column of cohesionless sand released on a rough floor, plane
strain (:class:`fempm.materials.DruckerPrager`).

The column, ``width`` :math:`L_0` wide and :math:`H_0 = a L_0` high (aspect ratio ``aspect``
:math:`a`), stands against a smooth wall (slip, the symmetry plane of a column twice as wide)
on a floor with Coulomb friction (``floor_friction``, :func:`fempm.boundary.friction`). It
starts at rest under its geostatic stress, :math:`\sigma_{yy} = -\rho g (H_0 - y)`,
:math:`\sigma_{xx} = \sigma_{zz} = K_0 \sigma_{yy}` with Jaky's :math:`K_0 = 1 - \sin\phi`,
and collapses under gravity. The results (:func:`deposit`) are the runout
:math:`(L_\infty - L_0)/L_0` and the final height :math:`H_\infty / L_0` of the deposit (its
extent and height: the outermost particles plus half a particle spacing), and the kinetic
energy left at the end as a fraction of the potential energy released (the deposit is at rest
when it is small).
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fempm.boundary.walls import friction, slip
from fempm.materials.drucker_prager import DruckerPrager
from fempm.particles.seeding import create_particles, per_direction
from fempm.scene.definition import Scene, check_counts, checked
from fempm.scenes.dims import axis, block_mesh, check_dim, lattice_ppc
from fempm.stepping.loads import Loads
from fempm.stepping.options import StepOptions

__all__ = ["RUNOUT_LAWS", "column_collapse", "deposit", "published_runout"]

#: the experimental runout laws :math:`(L_\infty - L_0)/L_0 = c_1 a` for :math:`a < a_1` and
#: :math:`c_2 a^{2/3}` for :math:`a > a_2` of quasi-two-dimensional columns in channels: Lube,
#: Huppert, Sparks and Freundt (2005), Phys. Rev. E 72, 041301, and Lajeunesse, Monnier and
#: Homsy (2005), Phys. Fluids 17, 103302, with the coefficients and ranges as Lagrée, Staron
#: and Popinet (2011), J. Fluid Mech. 686, 378-408, eqs. (3.1)-(3.2), quote them
#: (name -> (c1, a1, c2, a2))
RUNOUT_LAWS = {"Lube et al. 2005": (1.2, 1.8, 1.9, 2.8), "Lajeunesse et al. 2005": (1.8, 3.0, 2.3, 3.0)}


def published_runout(aspect: float) -> dict[str, tuple[float, float]]:
    """The runout of each law of :data:`RUNOUT_LAWS` at aspect ratio ``aspect``, as a range
    (low, high): one value inside a law's ranges, the two branches between them."""
    out = {}
    for name, (c1, a1, c2, a2) in RUNOUT_LAWS.items():
        linear, power = c1 * aspect, c2 * aspect ** (2.0 / 3.0)
        if aspect <= a1 and aspect < a2:
            out[name] = (linear, linear)
        elif aspect >= a2 and aspect > a1:
            out[name] = (power, power)
        else:  # between the ranges (or at a common bound): both branches
            out[name] = (min(linear, power), max(linear, power))
    return out


def deposit(scene: Scene, solver) -> dict:
    """The collapse's results (collective): ``runout`` :math:`(L_\\infty - L_0)/L_0`,
    ``final_height`` :math:`H_\\infty/L_0`, ``kinetic_fraction`` (kinetic energy over the
    potential energy released)."""
    p, prm = scene.particles, scene.params
    comm = p.comm
    half = prm["spacing"] / 2
    front = comm.allreduce(float(p.x[:, 0].max(initial=-np.inf)), op=MPI.MAX) + half
    top = comm.allreduce(float(p.x[:, 1].max(initial=-np.inf)), op=MPI.MAX) + half
    released = comm.allreduce(float(p.mass @ (p.fields["X0"][:, 1] - p.x[:, 1]))) * prm["g"]
    kinetic = solver.energies()["kinetic"]
    L0 = prm["width"]
    return {"runout": (front - L0) / L0, "final_height": top / L0,
            "kinetic_fraction": kinetic / released if released > 0 else np.inf}


@checked(positive=("aspect", "width", "rho", "E"), non_negative=("cohesion", "floor_friction", "g"))
def column_collapse(
    *, aspect: float = 1.0, width: float = 0.2, cells: int = 16, ppc: int | None = None, rho: float = 2000.0, E: float = 5.0e6,
    nu: float = 0.3, friction_angle: float = 30.0, dilation_angle: float = 0.0, cohesion: float = 0.0,
    floor_friction: float = 0.5, g: float = 9.81, t_end: float | None = None, scheme: str = "MUSL",
    flip: float = 0.99, cfl: float = 0.4, frames: int = 20, mass: str = "lumped", dim: int = 2,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> Scene:
    """The column collapse (see the module): ``cells`` square cells across the column width,
    ``ppc`` particles per cell (a lattice: 4 = 2 x 2 in 2D, 8 = 2 x 2 x 2 in 3D); the mesh reaches ``2 + 3 a`` column
    widths along the floor and ``1.05 a`` up. ``t_end`` defaults to :math:`6\\sqrt{H_0/g}` (the collapse ends
    after about :math:`3\\sqrt{H_0/g}`). With ``dim=3`` the column is a square one,
    :math:`L_0 \\times L_0` in plan, in a corner of two smooth walls (``x = 0`` and ``z = 0``: the
    symmetry planes of a column twice as wide both ways), y up, on hexahedra reaching ``2 + 3 a``
    widths along x and z; the runout is measured along x.

    Args:
        aspect: The column's height over its width, a = H0 / L0.
        width: The column's width L0 in m.
        cells: Cells across the column's width.
        ppc: Particles per cell, a lattice (None: 4 in 2D, 8 in 3D).
        rho: The density in kg/m^3.
        E: Young's modulus in Pa.
        nu: Poisson's ratio.
        friction_angle: Drucker-Prager's friction angle in degrees.
        dilation_angle: The dilation angle in degrees.
        cohesion: The cohesion in Pa.
        floor_friction: The floor's Coulomb coefficient.
        g: Gravity in m/s^2.
        t_end: The end time in s (None: 6 sqrt(H0 / g)).
        dim: 2 (plane strain) or 3 (a square column in a corner).
    """
    dim = check_dim(dim)
    ppc = lattice_ppc(ppc, dim)
    check_counts(cells=cells, ppc=ppc)
    if not 0.0 < aspect < np.inf or not 0.0 < width < np.inf:
        raise ValueError(f"column_collapse needs a positive aspect and width (got aspect={aspect}, width={width})")
    if not 0.0 <= floor_friction < np.inf:
        raise ValueError(f"floor_friction={floor_friction} must be >= 0")
    h = width / cells
    H0 = aspect * width
    nx, ny = int(np.ceil((2.0 + 3.0 * aspect) * cells)), int(np.ceil(1.05 * aspect * cells)) + 1
    n = [nx, ny] if dim == 2 else [nx, ny, nx]
    mesh = block_mesh(comm, [0.0] * dim, [k * h for k in n], n)
    p = create_particles(mesh, ppc, density=rho,
                         cells=lambda x: (x[0] < width) & (x[1] < H0) & ((x[2] < width) if dim == 3 else True))
    sand = DruckerPrager(E, nu, friction_angle=friction_angle, dilation_angle=dilation_angle, cohesion=cohesion)
    K0 = 1.0 - np.sin(np.radians(friction_angle))
    syy = -rho * g * (H0 - p.x[:, 1])
    sigma = np.zeros((len(p), dim, dim))
    sigma[:, 0, 0], sigma[:, 1, 1] = K0 * syy, syy
    if dim == 3:
        sigma[:, 2, 2] = K0 * syy
    else:
        p.fields["sigma_zz"] = K0 * syy
    p.fields["sigma"] = sigma
    if t_end is None:
        t_end = 6.0 * np.sqrt(H0 / g)
    params = dict(aspect=aspect, width=width, height=H0, cells=cells, ppc=ppc, rho=rho, E=E, nu=nu,
                  friction_angle=friction_angle, dilation_angle=dilation_angle, cohesion=cohesion,
                  floor_friction=floor_friction, g=g, K0=K0, spacing=h / per_direction(ppc, dim), scheme=scheme, flip=flip,
                  mass=mass, cfl=cfl, **({"dim": dim} if dim == 3 else {}))

    def bcs(V):
        walls = [slip(V, lambda x: np.isclose(x[0], 0.0), axis(0, dim, -1.0)),
                 friction(V, lambda x: np.isclose(x[1], 0.0), axis(1, dim, -1.0), floor_friction)]
        return walls + ([slip(V, lambda x: np.isclose(x[2], 0.0), axis(2, dim, -1.0))] if dim == 3 else [])

    return Scene(
        name="column_collapse", mesh=mesh, particles=p, materials=[sand], t_end=t_end,
        bcs=bcs, loads=Loads(body_force=axis(1, dim, -g)), options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl),
        frames=frames, params=params, results=deposit,
    )
