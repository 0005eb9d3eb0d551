"""Built-in scenes (the verification problems), usable from Python and from
``python -m fempm run NAME --option value``."""

from __future__ import annotations

from pathlib import Path

import dolfinx.mesh as dm
import numpy as np
from mpi4py import MPI

from fempm.boundary import fixed, slip
from fempm.domains import box_corners
from fempm.materials import LinearElastic, NeoHookean, NewtonianTait
from fempm.particles import Particles
from fempm.scene import Scene
from fempm.seeding import create_particles
from fempm.stepping import Loads, StepOptions

MESHES = Path(__file__).resolve().parents[1] / "meshes"


def vibrating_bar(
    cells: int = 16, ppc: int = 2, scheme: str = "USL", flip: float = 1.0, mass: str = "lumped",
    cfl: float = 0.5, t_end: float = 40.0, L: float = 25.0, E: float = 100.0, rho: float = 1.0,
    v0: float = 0.1, mode: int = 1, dim: int = 1, lumped_forces: bool = False, comm: MPI.Comm = MPI.COMM_WORLD,
) -> Scene:
    """Bar fixed at x = 0, free at x = L, first mode: v(x, 0) = v0 sin(beta x); ``dim=2`` runs
    it as a 2D strip of one cell height (nu = 0: plane stress = plane strain = 1D).

    Exact: v_cm(t) = v0 / (beta L) cos(omega t), beta = (2 mode - 1) pi / (2 L), omega = beta c.
    The mesh extends 4 cells past the free end so the bar can stretch.
    """
    h = L / cells
    if dim == 1:
        mesh = dm.create_interval(comm, cells + 4, [0.0, L + 4 * h])
    else:  # a strip one cell high (quadrilaterals), nu = 0: the same 1D solution
        mesh = dm.create_rectangle(comm, [[0.0, 0.0], [L + 4 * h, h]], [cells + 4, 1], dm.CellType.quadrilateral)
    p = create_particles(mesh, ppc**dim, density=rho, cells=lambda x: x[0] < L)
    beta = (2 * mode - 1) * np.pi / (2 * L)
    p.fields["v"] = np.zeros((len(p), dim))
    p.fields["v"][:, 0] = v0 * np.sin(beta * p.x[:, 0])
    params = dict(cells=cells, ppc=ppc, scheme=scheme, flip=flip, mass=mass, cfl=cfl, L=L, E=E, rho=rho, v0=v0,
                  beta=beta, omega=beta * np.sqrt(E / rho), dim=dim)
    return Scene(
        name="vibrating_bar", mesh=mesh, particles=p, materials=[LinearElastic(E, 0.0)], t_end=t_end,
        bcs=lambda V: [fixed(V, lambda x: np.isclose(x[0], 0.0))],
        options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl, lumped_forces=lumped_forces), params=params,
    )


def two_disks(
    mesh: str = "structured", cells: int = 20, ppc: int = 4, scheme: str = "MUSL", flip: float = 1.0,
    mass: str = "lumped", cfl: float = 0.4, t_end: float = 3.0, E: float = 1000.0, nu: float = 0.3,
    rho: float = 1000.0, speed: float = 0.1, radius: float = 0.2, frames: int = 30,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> Scene:
    """Two elastic disks (Sulsky, Chen and Schreyer 1994) on the unit square, plane strain.

    Disks of radius 0.2 at (0.2, 0.2) and (0.8, 0.8) moving at +-(0.1, 0.1); contact through
    the single-valued grid velocity; no boundary conditions (the disks never reach the walls).
    ``mesh``: "structured" (quadrilaterals, ``cells`` per side) or "unstructured"
    (triangles from ``meshes/unit_square_tri.msh``).
    """
    if mesh == "structured":
        m = dm.create_unit_square(comm, cells, cells, dm.CellType.quadrilateral)
    elif mesh == "unstructured":
        from fempm.meshes import read_msh

        m = read_msh(MESHES / "unit_square_tri.msh", comm, gdim=2).mesh
    else:
        raise ValueError(f"unknown option mesh={mesh!r}; expected structured or unstructured")
    centres = np.array([[0.2, 0.2], [0.8, 0.8]])

    def in_disks(x):
        return (np.hypot(x[0] - 0.2, x[1] - 0.2) < radius) | (np.hypot(x[0] - 0.8, x[1] - 0.8) < radius)

    p = create_particles(m, ppc, density=rho, where=in_disks)
    lower = np.hypot(*(p.x - centres[0]).T) < radius
    p.fields["v"] = np.where(lower[:, None], speed, -speed) * np.ones((len(p), 2))
    params = dict(mesh=mesh, cells=cells, ppc=ppc, scheme=scheme, flip=flip, mass=mass, cfl=cfl, E=E, nu=nu, rho=rho)
    return Scene(
        name="two_disks", mesh=m, particles=p, materials=[LinearElastic(E, nu)], t_end=t_end, frames=frames,
        options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl), params=params,
    )





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


def cantilever(
    cells: int = 4, ppc: int = 2, scheme: str = "MUSL", flip: float = 0.95, mass: str = "lumped",
    cfl: float = 0.4, t_end: float = 0.6, L: float = 0.7, H: float = 0.047, E: float = 6e7, nu: float = 0.0,
    rho: float = 1000.0, g: float = 10.0, material: str = "neo-hookean", degree: int = 1, mass_cutoff: float = 1e-9,
    domain: str = "point", frames: int = 20,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> Scene:
    r"""Cantilever under suddenly applied self-weight (VERIFICATION.md section 5).

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
    """
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
    p = create_particles(mesh, ppc**2, density=rho, cells=lambda x: (x[0] > 0) & (x[0] < L) & (x[1] > 0) & (x[1] < H),
                         corners=domain == "cpdi2")  # CPDI2: each particle is its sub-cell
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


def hanging_block(
    cells: int = 10, ppc: int = 3, domain: str = "point", mesh: str = "structured", scheme: str = "MUSL",
    flip: float = 0.99, mass: str = "lumped", cfl: float = 0.4, t_end: float = 0.5, g: float = 1000.0,
    E: float = 1e6, nu: float = 0.3, rho: float = 1050.0, frames: int = 10, comm: MPI.Comm = MPI.COMM_WORLD,
) -> Scene:
    r"""Unit block hanging from its top under extreme self-weight (VERIFICATION.md section 6):
    neo-Hookean, :math:`\rho g L / E \approx 1`, so the block stretches to several times its
    length. The block is :math:`[0, 1] \times [-1, 0]`, the grid velocity is zero at y > -h/2
    (one clamped row of cells above the block), and the mesh reaches down to y = -4.

    ``mesh``: "structured" (``cells`` quadrilaterals per unit length) or "unstructured"
    (triangles of about that size, with a row of vertices on the block's top y = 0). Particles carry their lattice index
    ``fields["lattice"]`` (i, j) for the neighbour-gap measure; with ``domain="cpdi2"`` each particle is its lattice
    square, ``fields["corners"]``.
    """
    h = 1.0 / cells
    box = [[-0.5, -4.0], [1.5, h]]
    if mesh == "structured":
        m = dm.create_rectangle(comm, box, [int(round(2 / h)), int(round((4 + h) / h))], dm.CellType.quadrilateral)
    elif mesh == "unstructured":
        from fempm.meshes import unstructured_rectangle

        m = unstructured_rectangle(comm, h, size=(2.0, 4.0 + h), origin=(-0.5, -4.0), split_y=(0.0,))
    else:
        raise ValueError(f"unknown option mesh={mesh!r}; expected structured or unstructured")
    # particles on a regular lattice of spacing h / ppc (also on the triangle mesh)
    n = cells * ppc
    s = (np.arange(n) + 0.5) / n
    X, Y = np.meshgrid(s, s - 1.0, indexing="ij")
    x = np.column_stack([X.ravel(), Y.ravel()]) if comm.rank == 0 else np.zeros((0, 2))
    lattice = np.column_stack(np.unravel_index(np.arange(n * n), (n, n))) if comm.rank == 0 else np.zeros((0, 2))
    vol = (1.0 / n) ** 2
    fields = {"lattice": lattice.astype(float), "lp": np.full((len(x), 2), 0.5 / n)}
    if domain == "cpdi2":  # each particle is its lattice square, tracked by its four corners
        fields["corners"] = box_corners(x, fields["lp"])
    p = Particles(m, x, rho * vol, vol, fields=fields)
    params = dict(cells=cells, ppc=ppc, domain=domain, mesh=mesh, scheme=scheme, flip=flip, mass=mass, cfl=cfl, g=g, E=E,
                  nu=nu, rho=rho, spacing=1.0 / n, h=h)
    return Scene(
        name="hanging_block", mesh=m, particles=p, materials=[NeoHookean(E, nu)], t_end=t_end, frames=frames,
        bcs=lambda V: [fixed(V, lambda x: x[1] > -0.5 * h)], loads=Loads(body_force=(0.0, -g)),
        options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl, domain=domain), params=params,
    )


def largest_neighbour_gap(particles) -> float:
    """Largest distance between lattice neighbours (right and lower) over all ranks, gathered
    on every rank (the hanging block's continuity measure)."""
    comm = particles.comm
    lat = np.concatenate(comm.allgather(particles.fields["lattice"].astype(np.int64)))
    x = np.concatenate(comm.allgather(particles.x))
    n = int(lat.max(initial=0)) + 1
    grid = np.full((n, n, 2), np.nan)
    grid[lat[:, 0], lat[:, 1]] = x
    gaps = [np.linalg.norm(np.diff(grid, axis=a), axis=-1) for a in (0, 1)]
    return float(max(np.nanmax(g_) for g_ in gaps))


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


def dam_break(
    cells: int = 10, ppc: int = 2, scheme: str = "MUSL", flip: float = 0.99, mass: str = "lumped",
    cfl: float = 0.4, t_end: float = 0.22, a: float = 0.1, box: float = 0.4, rho0: float = 1000.0,
    kappa: float = 2.0e4, gamma: float = 7.0, viscosity: float = 1.0e-3, g: float = 9.81, frames: int = 22,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> Scene:
    r"""Dam break (VERIFICATION.md section 9): a water column ``a`` wide and ``2 a`` high
    (n^2 = 2) at the left of a box ``box`` wide, slip walls left, right and at the bottom, open
    top; Tait water :math:`p = \kappa((\rho/\rho_0)^\gamma - 1)`.

    ``cells`` cells across the column width (square cells), ``ppc`` x ``ppc`` particles per
    cell. The column starts at rest in hydrostatic equilibrium: the particle density is
    :math:`\rho = \rho_0 (1 + \rho_0 g (2a - y) / \kappa)^{1/\gamma}` and its stress
    :math:`-p I`. Reference: the surge front of Martin and Moyce (1952), ``MARTIN_MOYCE``.
    """
    h = a / cells
    nx, ny = int(round(box / h)), int(round(3 * a / h))
    mesh = dm.create_rectangle(comm, [[0.0, 0.0], [nx * h, ny * h]], [nx, ny], dm.CellType.quadrilateral)
    H = 2 * a

    def density(x):
        return rho0 * (1 + rho0 * g * (H - x[:, 1]) / kappa) ** (1 / gamma)

    p = create_particles(mesh, ppc**2, density=density, cells=lambda x: (x[0] < a) & (x[1] < H))
    water = NewtonianTait(rho0=rho0, kappa=kappa, gamma=gamma, viscosity=viscosity)
    pressure = water.pressure(p.mass / p.volume)
    p.fields["sigma"] = -pressure[:, None, None] * np.eye(2)
    params = dict(cells=cells, ppc=ppc, scheme=scheme, flip=flip, mass=mass, cfl=cfl, a=a, box=nx * h, rho0=rho0,
                  kappa=kappa, gamma=gamma, viscosity=viscosity, g=g, spacing=h / ppc, time_scale=np.sqrt(2 * g / a))
    W = nx * h

    def bcs(V):
        return [slip(V, lambda x: np.isclose(x[0], 0.0) | np.isclose(x[0], W), (1.0, 0.0)),
                slip(V, lambda x: np.isclose(x[1], 0.0), (0.0, 1.0))]

    return Scene(
        name="dam_break", mesh=mesh, particles=p, materials=[water], t_end=t_end, frames=frames, bcs=bcs,
        loads=Loads(body_force=(0.0, -g)), options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl),
        params=params,
    )


SCENES = {"bar": vibrating_bar, "disks": two_disks, "cantilever": cantilever, "dam": dam_break, "block": hanging_block}
