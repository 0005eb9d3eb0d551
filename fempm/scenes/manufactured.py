r"""Scenes of the exact and manufactured solutions of :mod:`fempm.verification.manufactured`.

:func:`manufactured_scene` puts a problem on a background mesh of a given resolution: the
particles carry their reference positions ``fields["X0"]`` (the body force is
:math:`b(X, t)`, and :func:`fempm.verification.errors.particle_errors` compares :math:`x_p - X_p` with
:math:`u(X_p, t)`), start with the exact velocity (and, where the problem says so, at
:math:`X + u(X, 0)` with :math:`F(X, 0)`, its volume and stress), and the grid conditions
follow the problem's walls.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fempm.boundary.walls import fixed, slip
from fempm.meshes import structured as dm
from fempm.meshes.generators import unstructured_box, unstructured_rectangle
from fempm.particles.corners import domain_geometry
from fempm.particles.particle_set import Particles
from fempm.particles.seeding import create_particles
from fempm.scene.definition import Scene
from fempm.stepping.loads import Loads
from fempm.stepping.options import StepOptions
from fempm.transfer.domains import step_domain

__all__ = ["MESH_KINDS", "annulus_lattice", "background_mesh", "manufactured_scene"]

MESH_KINDS = ("structured", "triangles", "unstructured")


def background_mesh(lower, upper, cells_per_unit: float, kind: str, comm: MPI.Comm) -> dm.Mesh:
    """A mesh of the box ``[lower, upper]`` with about ``cells_per_unit`` cells per unit length:
    ``structured`` intervals / quadrilaterals / hexahedra, ``triangles`` (structured triangles
    or tetrahedra), or ``unstructured`` (gmsh triangles or tetrahedra of that size)."""
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    d = len(lo)
    n = [max(int(round((b - a) * cells_per_unit)), 1) for a, b in zip(lo, hi)]
    if kind not in MESH_KINDS:
        raise ValueError(f"unknown option mesh={kind!r}; expected one of {', '.join(MESH_KINDS)}")
    if d == 1:
        return dm.create_interval(comm, n[0], [lo[0], hi[0]])
    if kind == "unstructured":
        if d == 2:
            return unstructured_rectangle(comm, 1.0 / cells_per_unit, size=tuple(hi - lo), origin=tuple(lo))
        mesh = unstructured_box(comm, 1.0 / cells_per_unit, size=tuple(hi - lo))
        mesh.geometry.x[:, :3] += lo
        return mesh
    if d == 2:
        cell = dm.CellType.quadrilateral if kind == "structured" else dm.CellType.triangle
        return dm.create_rectangle(comm, [lo, hi], n, cell)
    cell = dm.CellType.hexahedron if kind == "structured" else dm.CellType.tetrahedron
    return dm.create_box(comm, [lo, hi], n, cell)


def annulus_lattice(r_in: float, r_out: float, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""Particles of an annulus on a polar lattice of about ``spacing``: rings of equal
    thickness, each split into equal angular sectors; every particle is the straight-sided
    quadrilateral of its sector's corners. Returns the centroids (n, 2), areas (n,) and corners
    (n, 4, 2) in :func:`fempm.transfer.domains.box_corners` order."""
    nr = max(int(round((r_out - r_in) / spacing)), 1)
    radii = np.linspace(r_in, r_out, nr + 1)
    corners = []
    for ra, rb in zip(radii[:-1], radii[1:]):  # loop over rings, not particles
        nt = max(int(round(np.pi * (ra + rb) / spacing)), 3)
        a = np.linspace(0.0, 2 * np.pi, nt + 1)
        e = np.column_stack([np.cos(a), np.sin(a)])  # unit vectors at the sector edges
        corners.append(np.stack([ra * e[:-1], ra * e[1:], rb * e[:-1], rb * e[1:]], axis=1))
    corners = np.concatenate(corners)
    _, _, area, centroid = domain_geometry(corners)
    return centroid, area, corners


def _body_particles(problem, mesh, h: float, ppc: int, domain: str) -> Particles:
    """The problem's body at its reference positions (particles not yet displaced)."""
    comm = mesh.comm
    corners = step_domain(domain).tracks_corners  # each particle its domain, tracked by its corners
    if problem.name == "generalized_vortex":
        spacing = h / round(ppc ** (1 / problem.dim))
        X, vol, C = annulus_lattice(problem.r_in, problem.r_out, spacing)
        if comm.rank != 0:
            X, vol, C = X[:0], vol[:0], C[:0]
        fields = {"corners": C} if corners else {}
        return Particles(mesh, X, problem.rho0 * vol, vol, fields=fields)
    lo, hi = np.array(problem.lower), np.array(problem.upper)

    def in_body(x):
        return np.all((x[: problem.dim].T >= lo - 1e-12) & (x[: problem.dim].T <= hi + 1e-12), axis=1)

    return create_particles(mesh, ppc, density=problem.rho0, cells=in_body, corners=corners)


def _start_displaced(problem, particles: Particles) -> None:
    r"""Move the particles (and CPDI2 corners) to :math:`X + u(X, 0)` with :math:`F(X, 0)`,
    volume :math:`J V^0` and the material's stress (collective: particles may change rank)."""
    f = particles.fields
    X = f["X0"]
    F = problem.deformation_gradient(X, 0.0)
    J = np.linalg.det(F)
    f["F"] = F
    if "corners" in f:
        C = f["corners"]
        n, k, d = C.shape
        f["corners"] = C + problem.displacement(C.reshape(n * k, d), 0.0).reshape(n, k, d)
        _, _, volume, particles.x = domain_geometry(f["corners"], particles.comm)
    else:
        volume = J * f["volume0"]
        particles.x = X + problem.displacement(X, 0.0)
    particles.volume = volume
    rho = particles.mass / volume
    f["sigma"] = problem.material.stress(F, np.zeros_like(F), np.zeros_like(F), 0.0, rho)
    particles.relocate()


def manufactured_scene(
    problem, cells: int = 16, *, mesh: str = "structured", ppc: int | None = None, degree: int = 1,
    variant: str | None = None, mass: str = "lumped", domain: str = "point", scheme: str = "MUSL",
    flip: float = 1.0, cfl: float = 0.4, dt: float | None = None, t_end: float | None = None,
    frames: int = 10, comm: MPI.Comm = MPI.COMM_WORLD, **options,
) -> Scene:
    """A scene of ``problem`` (:mod:`fempm.verification.manufactured`) with ``cells`` cells per unit length
    of the reference body's largest side (per side of the background square for the vortex;
    per bar length for the bar).

    ``ppc``: particles per cell (default 2 per direction); ``mesh``: see
    :func:`background_mesh`; ``degree``/``variant``: the velocity space; ``mass``,
    ``domain``, ``scheme``, ``flip``, ``cfl`` and further ``options``: :class:`StepOptions`;
    ``dt``: a fixed time step (default the CFL step); ``t_end``: default the problem's.
    """
    d = problem.dim
    ppc = ppc if ppc is not None else 2**d
    lo, hi = problem.lower, problem.upper
    if problem.name == "generalized_vortex":
        blo, bhi = problem.background(0.0)
        per_unit = cells / (bhi[0] - blo[0])
    else:
        per_unit = cells / max(b - a for a, b in zip(lo, hi))
        blo, bhi = problem.background(1.0 / per_unit)
    m = background_mesh(blo, bhi, per_unit, mesh, comm)
    p = _body_particles(problem, m, 1.0 / per_unit, ppc, domain)
    p.fields["X0"] = p.x.copy()
    p.fields["volume0"] = p.volume.copy()
    if problem.start_displaced:
        _start_displaced(problem, p)
    p.fields["v"] = problem.velocity(p.fields["X0"], 0.0)
    loads = Loads()
    if problem.has_body_force:
        loads = Loads(body_force=lambda x, t, X: problem.body_force(X, t))

    def bcs(V):
        out = []
        for axis, value, kind in problem.walls():
            def where(x, a=axis, v=value):
                return np.isclose(x[a], v, atol=1e-10 * max(1.0, abs(v)))
            out.append(fixed(V, where) if kind == "fixed" else slip(V, where, np.eye(d)[axis]))
        return out

    params = dict(problem=problem.name, cells=cells, h=1.0 / per_unit, mesh=mesh, ppc=ppc, degree=degree,
                  variant=variant or "default", mass=mass, domain=domain, scheme=scheme, flip=flip, cfl=cfl, dt=dt)
    return Scene(
        name=problem.name, mesh=m, particles=p, materials=[problem.material],
        t_end=problem.t_end if t_end is None else t_end, bcs=bcs, loads=loads,
        options=StepOptions(scheme=scheme, flip=flip, mass=mass, cfl=cfl, domain=domain, **options),
        degree=degree, variant=variant, frames=frames, params=params, dt=dt,
    )

