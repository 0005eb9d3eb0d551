r"""Cook's membrane (docs/verification.md) on an unstructured triangle mesh, loaded to a
static state, and its small-strain finite element reference.

The tapered panel :math:`A(0, 0), B(48, 44), C(48, 60), D(0, 44)` is clamped on its left edge
and carries a uniform vertical shear traction on its right edge :math:`BC` (length 16) of total
force ``load``; linear elasticity, plane strain (:class:`fempm.materials.LinearElastic`). The
background mesh is the panel itself, meshed by gmsh with triangles of size ``h``.

By default the particles are seeded per triangle (:func:`fempm.particles.create_particles`,
``ppc`` per triangle, each the centroid of a sub-triangle with its area): every triangle's
particles then hold its area exactly, the particles integrate the P1 stiffness exactly (constant
strain per triangle), and the traction is applied as the finite element's consistent nodal load
(:func:`fempm.boundary.consistent_load.consistent_weights`: the weights of the particles of the
triangles along :math:`BC`, in ``fields["area"]``). The quasi-static answer is then the P1
finite element solution on the same mesh, and converges as it does (first order in h; a
lattice seeding's particles weigh each triangle by the area they happen to hold, which stays
2-6 % wrong at every h, docs/convergence.md).

With ``spacing`` the particles sit on a lattice of the panel's bilinear map
:math:`x(\xi, \eta) = (1-\xi)(1-\eta) A + \xi (1-\eta) B + \xi\eta C + (1-\xi)\eta D`: each is the
quadrilateral of its lattice cell (centroid, area, and the corners for CPDI2), and the particles
of the last lattice column own exact pieces of :math:`BC` and the traction times those lengths
(``fields["area"]``) applies exactly ``load``. The load acts
from :math:`t = 0` and mass-proportional grid damping at about twice the first eigenfrequency
brings the panel to rest: the result is the static displacement of the corner :math:`C`.
"""

from __future__ import annotations

import basix
import dolfinx.mesh
import numpy as np
from mpi4py import MPI

from fempm.boundary.consistent_load import consistent_weights

from fempm.boundary.walls import fixed
from fempm.materials.base import lame
from fempm.materials.linear_elastic import LinearElastic
from fempm.meshes.generators import unstructured_polygon
from fempm.particles.corners import domain_geometry
from fempm.particles.particle_set import Particles
from fempm.particles.seeding import create_particles
from fempm.scene.definition import VARIANTS, Scene, check_counts, checked, dofs_per_cell, emptiest_cell
from fempm.stepping.loads import Loads
from fempm.stepping.options import StepOptions
from fempm.transfer.domains import step_domain

__all__ = [
    "CORNERS", "EDGE", "FE_REFERENCE", "cook_membrane", "corner_displacement", "displacement_reference", "fe_reference",
    "first_frequency",
    "panel_lattice", "panel_map", "value_at_corner",
]

#: the vertical displacement of C per unit load, converged, by Poisson's ratio: the Taylor-Hood
#: P2/P1, P3/P2 and P4/P3 solutions (:func:`fe_reference`) at h = 2, 1, 0.5 extrapolated by
#: Richardson at their fitted order (about 1: the clamped corners' singularities), which agree
#: within 1.1e-3 (``python benchmarks/cook_reference.py``, docs/convergence.md)
FE_REFERENCE = {1 / 3: 22.611, 0.4999: 19.429}
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
    *, h: float = 3.0, nu: float = 1 / 3, E: float = 1.0, rho: float = 1.0, load: float = 1e-3, spacing: float | None = None,
    degree: int = 1, variant: str | None = None, mass: str = "lumped", domain: str = "point", scheme: str = "MUSL",
    flip: float = 1.0, cfl: float = 0.4, damping: float | None = None, t_end: float | None = None, frames: int = 10,
    ppc: int | None = None, refine: int = 0, comm: MPI.Comm = MPI.COMM_WORLD,
) -> Scene:
    """Cook's membrane with triangles of size ``h`` and ``ppc`` particles seeded per triangle
    (default 4 for degree 1, 9 for degree 2: at least as many as the element's basis functions),
    the traction as the consistent nodal load; or, with ``spacing``, on the panel's lattice of that
    spacing (with degree 2 a given spacing must leave every triangle at least 6 particles).
    ``damping`` defaults to :math:`2\\omega_1` with :math:`\\omega_1` estimated from a cantilever
    of the panel's mean height; ``t_end`` to :math:`12 / \\omega_1`.

    Args:
        h: The triangles' size (the panel is 48 long).
        nu: Poisson's ratio.
        E: Young's modulus.
        rho: The density.
        load: The shear traction on the right edge (total, per unit thickness).
        spacing: A lattice of this spacing instead of ``ppc`` per triangle (None: per triangle).
        variant: The Lagrange variant of the velocity space, such as "bernstein" (None: DOLFINx's default).
        damping: The grid damping rate in 1/s (None: twice the estimated first frequency).
        t_end: The end time (None: 12 over the estimated first frequency).
        ppc: Particles per triangle (None: 4 for degree 1, 9 for degree 2).
        refine: Uniform refinements of a coarser gmsh mesh: gmsh meshes at 2^refine times the cell size and every rank splits its triangles refine times (:mod:`fempm.meshes.refinement`; a large mesh made in parallel).
    """
    check_counts(degree=degree)
    if spacing is not None and not 0.0 < spacing < np.inf:
        raise ValueError(f"spacing={spacing} must be a positive length")
    if variant is not None and variant not in VARIANTS:
        raise ValueError(f"unknown option variant={variant!r}; expected one of {', '.join(VARIANTS)}")
    if spacing is not None and ppc is not None:
        raise ValueError(f"spacing={spacing} and ppc={ppc} are two seedings: give one of them")
    mesh = unstructured_polygon(comm, CORNERS, h, refine=refine)
    # degree >= 2 needs every triangle to hold as many particles as dofs: the consistent mass
    # would be singular, and the particles' quadrature of the stiffness would leave zero-energy
    # modes (the implicit step's tangent is then singular, the explicit step rings in them)
    needed = dofs_per_cell("triangle", degree) if degree > 1 else 0
    if spacing is None:
        ppc = (4 if degree == 1 else 9) if ppc is None else ppc
        p = _per_triangle_particles(mesh, ppc, rho, degree, variant, domain)
        nx = ny = None
        if emptiest_cell(p) < needed:
            raise ValueError(f"ppc={ppc} particles per triangle are fewer than the {needed} basis functions of "
                             f"degree {degree}: give ppc >= {needed}")
    else:
        p, nx, ny = _lattice_particles(mesh, spacing, rho, domain, comm)
        if emptiest_cell(p) < needed:
            raise ValueError(f"spacing={spacing} leaves {emptiest_cell(p)} particle(s) in the emptiest triangle; "
                             f"degree {degree} needs {needed} in every one: give a smaller "
                             "spacing, or leave it unset (the particles are then seeded per triangle)")
    omega1 = first_frequency(E, nu, rho)
    traction = np.array([0.0, load / EDGE])

    def tractions(t):
        return p.fields["loaded"][:, None] * traction

    params = dict(h=h, nu=nu, E=E, rho=rho, load=load, spacing=spacing, ppc=ppc, lattice=(nx, ny), degree=degree,
                  mass=mass, domain=domain, scheme=scheme, omega1=omega1, **({"refine": refine} if refine else {}))
    return Scene(
        name="cook_membrane", mesh=mesh, particles=p, materials=[LinearElastic(E, nu)],
        t_end=12.0 / omega1 if t_end is None else t_end, frames=frames,
        bcs=lambda V: [fixed(V, lambda x: x[0] < 1e-9)], loads=Loads(traction=tractions),
        options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl, domain=domain,
                            damping=2.0 * omega1 if damping is None else damping),
        degree=degree, variant=variant, params=params,
        results=lambda scene, solver: {"corner_displacement": corner_displacement(solver.particles).tolist()},
    )


def _per_triangle_particles(mesh, ppc: int, rho: float, degree: int, variant: str | None, domain: str) -> Particles:
    """``ppc`` particles per triangle (:func:`fempm.particles.create_particles`) with the weights of
    the consistent load on :math:`BC` in ``fields["area"]`` (:func:`consistent_weights`). Collective."""
    p = create_particles(mesh, ppc, density=rho, corners=step_domain(domain).tracks_corners)
    lagrange = basix.LagrangeVariant.gll_warped if variant is None else getattr(basix.LagrangeVariant, variant)
    element = basix.create_element(basix.ElementFamily.P, basix.CellType.triangle, degree, lagrange)
    edge = dolfinx.mesh.locate_entities_boundary(mesh, 1, lambda x: np.isclose(x[0], CORNERS[1, 0]))
    w = consistent_weights(p, edge, element)
    p.fields["area"], p.fields["loaded"] = w, (w != 0.0).astype(float)
    return p


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
    """Displacement of the corner C (48, 60), gathered from all ranks: the linear least-squares
    fit of the particle displacements :math:`x_p - X_p` evaluated at C, over the particles seeded
    in the largest triangle at C (reference positions ``fields["X0"]`` inside it) when it holds
    at least 3, else over the 8 particles nearest to C. With particles seeded per triangle the
    P1 displacement is linear over that triangle and the fit returns its nodal value at C; the
    nearest particles of a lattice straddle triangles and extrapolate across their kinks."""
    comm = particles.comm
    X0 = particles.fields["X0"]
    C = CORNERS[2]
    d = np.linalg.norm(X0 - C, axis=1)
    inside = _in_triangle(X0, _triangle_at(particles.mesh, C))
    fit_cell = comm.allreduce(int(inside.sum())) >= 3
    near = np.flatnonzero(inside) if fit_cell else np.argsort(d)[:8]
    rows = np.concatenate(comm.allgather(np.column_stack([X0[near], particles.x[near] - X0[near], d[near]])))
    if not fit_cell:
        rows = rows[np.argsort(rows[:, 4])[:8]]
    A = np.column_stack([np.ones(len(rows)), rows[:, 0] - C[0], rows[:, 1] - C[1]])
    coef, *_ = np.linalg.lstsq(A, rows[:, 2:4], rcond=None)
    return coef[0]


def _triangle_at(mesh, point: np.ndarray) -> np.ndarray:
    """The vertices (3, 2) of the largest triangle with a vertex at ``point``, over all ranks."""
    x = mesh.geometry.x[:, :2]
    cells = mesh.geometry.dofmaps[0][:, :3]
    touching = np.any(np.linalg.norm(x[cells] - point, axis=2) < 1e-9, axis=1)
    tris = np.concatenate(mesh.comm.allgather(x[cells[touching]]))
    e1, e2 = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    area = np.round(np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]), 12)
    best = np.lexsort((tris.reshape(len(tris), -1).sum(axis=1), -area))[0]
    return tris[best]


def _in_triangle(x: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Which points (n, 2) lie in the triangle ``tri`` (3, 2) (boundary included)."""
    T = np.column_stack([tri[1] - tri[0], tri[2] - tri[0]])
    lam = np.linalg.solve(T, (x - tri[0]).T).T
    tol = 1e-12
    return (lam[:, 0] >= -tol) & (lam[:, 1] >= -tol) & (lam.sum(axis=1) <= 1 + tol)


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
    import ufl

    if degree < 2:
        raise ValueError(f"degree={degree}: Taylor-Hood needs a displacement degree of at least 2")
    mesh = unstructured_polygon(comm, CORNERS, h)
    cell = mesh.basix_cell()
    W = dolfinx.fem.functionspace(mesh, basix.ufl.mixed_element([
        basix.ufl.element("Lagrange", cell, degree, shape=(2,)), basix.ufl.element("Lagrange", cell, degree - 1)]))
    (u, p), (v, q) = ufl.TrialFunctions(W), ufl.TestFunctions(W)
    lam, mu = _moduli(mesh, E, nu)
    eps = ufl.sym
    a = (2 * mu * ufl.inner(eps(ufl.grad(u)), eps(ufl.grad(v))) + p * ufl.div(v) + q * ufl.div(u) - p * q / lam) * ufl.dx
    V0, _ = W.sub(0).collapse()
    w = _solve_panel(a, v, load, (W.sub(0), V0), V0, "fempm_cook_fe_")
    return value_at_corner(w.sub(0).collapse())


def displacement_reference(nu: float, h: float = 1.0, E: float = 1.0, load: float = 1.0,
                           comm: MPI.Comm = MPI.COMM_SELF, degree: int = 1) -> np.ndarray:
    r"""Displacement of C from the displacement-based :math:`P_k` finite element solution on the
    scene's own mesh of size ``h`` (:math:`(2\mu\,\varepsilon(u), \varepsilon(v)) +
    (\lambda \operatorname{div} u, \operatorname{div} v) = (\bar t, v)_{BC}`, MUMPS): what the
    scene's per-triangle particles integrate exactly with degree 1, locking as :math:`\nu \to 1/2`
    as they do."""
    import dolfinx.fem
    import ufl

    mesh = unstructured_polygon(comm, CORNERS, h)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", degree, (2,)))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    lam, mu = _moduli(mesh, E, nu)
    eps = lambda w: ufl.sym(ufl.grad(w))  # noqa: E731
    a = (2 * mu * ufl.inner(eps(u), eps(v)) + lam * ufl.div(u) * ufl.div(v)) * ufl.dx
    return value_at_corner(_solve_panel(a, v, load, V, V, "fempm_cook_p1_"))


def _moduli(mesh, E: float, nu: float):
    """The Lame parameters as DOLFINx constants: one compiled form for every E and nu."""
    import dolfinx.fem

    return tuple(dolfinx.fem.Constant(mesh, float(c)) for c in lame(E, nu))


def _solve_panel(a, v, load: float, clamped_space, V0, prefix: str):
    """Solve ``a = (t, v)_BC`` with the left edge clamped (the ``clamped_space``'s dofs at x = 0),
    the traction ``load / |BC|`` upwards on BC; MUMPS. Collective."""
    import dolfinx.fem
    import dolfinx.fem.petsc
    import ufl

    mesh = V0.mesh
    facets = dolfinx.mesh.locate_entities_boundary(mesh, 1, lambda x: np.isclose(x[0], CORNERS[1, 0]))
    tags = dolfinx.mesh.meshtags(mesh, 1, facets, np.full(len(facets), 1, dtype=np.int32))
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tags)
    L = ufl.inner(dolfinx.fem.Constant(mesh, np.array([0.0, load / EDGE])), v) * ds(1)  # load a constant too
    clamp = dolfinx.fem.locate_dofs_geometrical(clamped_space, lambda x: np.isclose(x[0], 0.0))
    zero = dolfinx.fem.Function(V0)
    bc = (dolfinx.fem.dirichletbc(zero, clamp, clamped_space[0]) if isinstance(clamped_space, tuple)
          else dolfinx.fem.dirichletbc(zero, clamp))
    problem = dolfinx.fem.petsc.LinearProblem(a, L, bcs=[bc], petsc_options_prefix=prefix, petsc_options={
        "ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"})
    w = problem.solve()
    return w[0] if isinstance(w, tuple) else w


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
