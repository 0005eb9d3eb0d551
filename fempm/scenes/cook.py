r"""Cook's membrane (docs/verification.md) on an unstructured triangle mesh, loaded to a
static state, and its small-strain finite element reference.

The tapered panel :math:`A(0, 0), B(48, 44), C(48, 60), D(0, 44)` is clamped on its left edge
and carries a uniform vertical shear traction on its right edge :math:`BC` (length 16) of total
force ``load``; linear elasticity, plane strain (:class:`fempm.materials.LinearElastic`). The
background mesh is the panel itself, meshed by gmsh with triangles of size ``h``.

Particles sit on a lattice of the panel's bilinear map
:math:`x(\xi, \eta) = (1-\xi)(1-\eta) A + \xi (1-\eta) B + \xi\eta C + (1-\xi)\eta D`: each is the
quadrilateral of its lattice cell (centroid, area, and the corners for CPDI2), so the particles
of the last lattice column own exact pieces of :math:`BC` and the traction times those lengths
(``fields["area"]``) applies exactly ``load`` at any number of particles per cell. The load acts
from :math:`t = 0` and mass-proportional grid damping at about twice the first eigenfrequency
brings the panel to rest: the result is the static displacement of the corner :math:`C`.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fempm.boundary.walls import fixed
from fempm.materials.base import lame
from fempm.materials.linear_elastic import LinearElastic
from fempm.meshes.generators import unstructured_polygon
from fempm.particles.corners import domain_geometry
from fempm.particles.particle_set import Particles
from fempm.scene.definition import Scene, check_counts, checked, dofs_per_cell, emptiest_cell
from fempm.stepping.loads import Loads
from fempm.stepping.options import StepOptions
from fempm.transfer.domains import step_domain

__all__ = [
    "CORNERS", "EDGE", "cook_membrane", "corner_displacement", "fe_reference", "first_frequency",
    "panel_lattice", "panel_map", "value_at_corner",
]

CORNERS = np.array([[0.0, 0.0], [48.0, 44.0], [48.0, 60.0], [0.0, 44.0]])  # A, B, C, D
EDGE = 16.0  # length of the loaded edge BC


def panel_map(xi: np.ndarray, eta: np.ndarray) -> np.ndarray:
    """The bilinear map of the unit square onto the panel, points (n, 2)."""
    A, B, C, D = CORNERS
    xi, eta = np.asarray(xi)[:, None], np.asarray(eta)[:, None]
    return (1 - xi) * (1 - eta) * A + xi * (1 - eta) * B + xi * eta * C + (1 - xi) * eta * D


def panel_lattice(nx: int, ny: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Particles of an ``nx`` x ``ny`` lattice of the panel: centroids (n, 2), areas (n,),
    corners (n, 4, 2) (:func:`fempm.transfer.domains.box_corners` order) and lattice column index (n,)."""
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    i, j = i.ravel(), j.ravel()
    corners = np.stack([panel_map((i + a) / nx, (j + b) / ny) for a, b in ((0, 0), (0, 1), (1, 0), (1, 1))], axis=1)
    _, _, area, centroid = domain_geometry(corners)
    return centroid, area, corners, i


@checked(positive=("h", "E", "rho"), non_negative=("damping",))
def cook_membrane(
    h: float = 3.0, nu: float = 1 / 3, E: float = 1.0, rho: float = 1.0, load: float = 1e-3, spacing: float | None = None,
    degree: int = 1, variant: str | None = None, mass: str = "lumped", domain: str = "point", scheme: str = "MUSL",
    flip: float = 1.0, cfl: float = 0.4, damping: float | None = None, t_end: float | None = None, frames: int = 10,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> Scene:
    """Cook's membrane with triangles of size ``h``; particle lattice ``spacing`` (default h / 2:
    two particles per cell size and direction; with degree 2 it is refined
    until every triangle holds at least 6 particles, and a given one that leaves fewer is an
    error). ``damping``
    defaults to :math:`2\\omega_1` with :math:`\\omega_1` estimated from a cantilever of the
    panel's mean height; ``t_end`` to :math:`12 / \\omega_1`."""
    check_counts(degree=degree)
    if spacing is not None and not 0.0 < spacing < np.inf:
        raise ValueError(f"spacing={spacing} must be a positive length")
    mesh = unstructured_polygon(comm, CORNERS, h)
    # degree >= 2 needs every triangle to hold as many particles as dofs: the consistent mass
    # would be singular, and the particles' quadrature of the stiffness would leave zero-energy
    # modes (the implicit step's tangent is then singular, the explicit step rings in them)
    needed = dofs_per_cell("triangle", degree) if degree > 1 else 0
    s = h / 2 if spacing is None else spacing
    while True:
        p, nx, ny = _lattice_particles(mesh, s, rho, domain, comm)
        if not needed or emptiest_cell(p) >= needed:
            break
        if spacing is not None:
            raise ValueError(f"spacing={spacing} leaves {emptiest_cell(p)} particle(s) in the emptiest triangle; "
                             f"degree {degree} needs {needed} in every one: give a smaller "
                             "spacing, or leave it unset (the scene then refines its lattice until each has them)")
        s *= 0.8
    omega1 = first_frequency(E, nu, rho)
    traction = np.array([0.0, load / EDGE])

    def tractions(t):
        return p.fields["loaded"][:, None] * traction

    params = dict(h=h, nu=nu, E=E, rho=rho, load=load, spacing=s, lattice=(nx, ny), degree=degree, mass=mass,
                  domain=domain, scheme=scheme, omega1=omega1)
    return Scene(
        name="cook_membrane", mesh=mesh, particles=p, materials=[LinearElastic(E, nu)],
        t_end=12.0 / omega1 if t_end is None else t_end, frames=frames,
        bcs=lambda V: [fixed(V, lambda x: x[0] < 1e-9)], loads=Loads(traction=tractions),
        options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl, domain=domain,
                            damping=2.0 * omega1 if damping is None else damping),
        degree=degree, variant=variant, params=params,
        results=lambda scene, solver: {"corner_displacement": corner_displacement(solver.particles).tolist()},
    )


def _lattice_particles(mesh, s: float, rho: float, domain: str, comm) -> tuple[Particles, int, int]:
    """The panel's particles on a lattice of about ``s`` (:func:`panel_lattice`), with the
    loaded edge's lengths in ``fields["area"]``; (particles, nx, ny). Collective."""
    nx, ny = max(int(round(48.0 / s)), 1), max(int(round(30.0 / s)), 1)
    x, area, corners, column = panel_lattice(nx, ny)
    if comm.rank != 0:
        x, area, corners, column = x[:0], area[:0], corners[:0], column[:0]
    fields = {"area": np.where(column == nx - 1, EDGE / ny, 0.0), "loaded": (column == nx - 1).astype(float)}
    if step_domain(domain).tracks_corners:
        fields["corners"] = corners
    return Particles(mesh, x, rho * area, area, fields=fields), nx, ny


def first_frequency(E: float, nu: float, rho: float) -> float:
    r"""Estimate of the panel's first eigenfrequency: a clamped Euler-Bernoulli beam of length 48
    and the panel's mean height 30, :math:`1.875^2 \sqrt{E' I / (\rho A L^4)}`, plane-strain
    modulus :math:`E' = E / (1 - \nu^2)`."""
    H, L = 30.0, 48.0
    return 1.875104**2 * np.sqrt(E / (1 - nu**2) * H**2 / 12 / (rho * L**4))


def corner_displacement(particles) -> np.ndarray:
    """Displacement of the corner C (48, 60): the linear least-squares fit of the particle
    displacements :math:`x_p - X_p` over the 8 particles nearest to C (reference positions),
    evaluated at C; gathered from all ranks."""
    comm = particles.comm
    X0 = particles.fields["X0"]
    C = CORNERS[2]
    d = np.linalg.norm(X0 - C, axis=1)
    near = np.argsort(d)[:8]
    rows = np.concatenate(comm.allgather(np.column_stack([X0[near], particles.x[near] - X0[near], d[near]])))
    rows = rows[np.argsort(rows[:, 4])[:8]]
    A = np.column_stack([np.ones(len(rows)), rows[:, 0] - C[0], rows[:, 1] - C[1]])
    coef, *_ = np.linalg.lstsq(A, rows[:, 2:4], rcond=None)
    return coef[0]


def fe_reference(nu: float, h: float = 1.0, E: float = 1.0, load: float = 1.0, comm: MPI.Comm = MPI.COMM_SELF,
                 degree: int = 2) -> np.ndarray:
    r"""Displacement of C from the small-strain, plane-strain finite element solution of the
    same panel: Taylor-Hood :math:`P_k/P_{k-1}` displacement-pressure elements (``degree`` k >= 2;
    no locking as :math:`\nu \to 1/2`), :math:`p = \lambda \operatorname{div} u`, on gmsh
    triangles of size ``h``, solved with MUMPS:

    .. math::
        (2\mu\, \varepsilon(u), \varepsilon(v)) + (p, \operatorname{div} v) = (\bar t, v)_{BC}, \qquad
        (\operatorname{div} u, q) - (p, q) / \lambda = 0 .
    """
    import basix.ufl
    import dolfinx.fem
    import dolfinx.fem.petsc
    import dolfinx.mesh
    import ufl

    mesh = unstructured_polygon(comm, CORNERS, h)
    cell = mesh.basix_cell()
    if degree < 2:
        raise ValueError(f"degree={degree}: Taylor-Hood needs a displacement degree of at least 2")
    W = dolfinx.fem.functionspace(mesh, basix.ufl.mixed_element([
        basix.ufl.element("Lagrange", cell, degree, shape=(2,)), basix.ufl.element("Lagrange", cell, degree - 1)]))
    (u, p), (v, q) = ufl.TrialFunctions(W), ufl.TestFunctions(W)
    lam, mu = lame(E, nu)
    eps = ufl.sym
    facets = dolfinx.mesh.locate_entities_boundary(mesh, 1, lambda x: np.isclose(x[0], 48.0))
    tags = dolfinx.mesh.meshtags(mesh, 1, facets, np.full(len(facets), 1, dtype=np.int32))
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tags)
    a = (2 * mu * ufl.inner(eps(ufl.grad(u)), eps(ufl.grad(v))) + p * ufl.div(v) + q * ufl.div(u) - p * q / lam) * ufl.dx
    t_bar = dolfinx.fem.Constant(mesh, np.array([0.0, load / EDGE]))
    L = ufl.inner(t_bar, v) * ds(1)
    V0, _ = W.sub(0).collapse()
    clamp = dolfinx.fem.locate_dofs_geometrical((W.sub(0), V0), lambda x: np.isclose(x[0], 0.0))
    zero = dolfinx.fem.Function(V0)
    bc = dolfinx.fem.dirichletbc(zero, clamp, W.sub(0))
    problem = dolfinx.fem.petsc.LinearProblem(
        a, L, bcs=[bc], petsc_options_prefix="fempm_cook_fe_",
        petsc_options={"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"})
    w = problem.solve()
    w = w[0] if isinstance(w, tuple) else w
    return value_at_corner(w.sub(0).collapse())


def value_at_corner(uh) -> np.ndarray:
    """The value (2,) of a finite element field ``uh`` at the corner C (48, 60), gathered from
    the rank whose cell holds it. Collective."""
    import dolfinx.geometry

    mesh = uh.function_space.mesh
    tree = dolfinx.geometry.bb_tree(mesh, mesh.topology.dim)
    C = np.array([[48.0, 60.0, 0.0]])
    cells = dolfinx.geometry.compute_colliding_cells(mesh, dolfinx.geometry.compute_collisions_points(tree, C), C)
    local = uh.eval(C, cells.links(0)[:1]) if len(cells.links(0)) else np.full(2, np.nan)
    vals = [r for r in mesh.comm.allgather(np.asarray(local).ravel()) if np.all(np.isfinite(r))]
    return vals[0]
