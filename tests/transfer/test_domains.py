"""Particle domains (GIMP, CPDI1, CPDI2): the averaged basis keeps the partition of unity and,
on affine cells, linear completeness; the consistent projection with averaged bases reproduces
linear fields; mass and momentum are conserved. On 1 and 2 ranks: sample points beyond a rank's
ghost cells are evaluated by the rank that owns them (:mod:`fempm.particles.halo`)."""

import dolfinx.fem as fem
import dolfinx.mesh as dm
import fempm
import numpy as np
import pytest
from conftest import make_mesh
from mpi4py import MPI

from fempm.transfer.basis import ParticleBasis
from fempm.transfer.domains import CPDI1, CPDI2, GIMP, domain_geometry, half_widths, make_domain
from fempm.particles.corners import box_corners
from fempm.meshes import unstructured_rectangle
from fempm.stepping import cell_sizes

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD
SIMPLICES = ("interval", "triangle", "tetrahedron", "unstructured-triangle", "unstructured-tetrahedron")
AFFINE = ("interval", "triangle", "quadrilateral", "tetrahedron", "hexahedron", "unstructured-triangle",
          "unstructured-tetrahedron")


def deformed_particles(mesh, name):
    """Jittered particles in the middle of the mesh, with a random F; CPDI2 corners of a
    sheared simplex (``fields["simplex"]``) and of a sheared, non-parallelogram box
    (``fields["box"]``), neither centred at the particle."""
    d = mesh.geometry.dim
    x0 = mesh.geometry.x[:, :d]
    lo, hi = x0.min(axis=0, initial=np.inf), x0.max(axis=0, initial=-np.inf)
    comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
    comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
    lo, hi = lo + 0.25 * (hi - lo), hi - 0.25 * (hi - lo)

    def middle(x):
        inside = np.all((x[:d].T > lo) & (x[:d].T < hi), axis=1)
        if name == "unstructured-triangle":  # the plate-with-hole mesh: stay off the hole
            inside &= np.hypot(x[0] - 0.5, x[1] - 0.5) > 0.3
        return inside

    p = fempm.create_particles(mesh, 4 if d < 3 else 27, density=2.0, jitter=0.5, seed=3, where=middle)
    A = np.eye(d) + 0.15 * np.sin(np.outer(p.ids, np.arange(1, d * d + 1))).reshape(-1, d, d)
    p.fields["F"] = A
    s = np.vstack([np.zeros(d), np.eye(d)])
    s -= s.mean(axis=0)
    h = np.ptp(x0, axis=0).max() / 40
    p.fields["simplex"] = p.x[:, None, :] + h * np.einsum("nij,kj->nki", A, s + 0.1)
    box = box_corners(p.x, np.full((len(p), d), h))
    box = p.x[:, None, :] + np.einsum("nij,nkj->nki", A, box - p.x[:, None, :])
    box[:, -1] += 0.2 * h  # the last corner off the parallelogram (a general quadrilateral/hexahedron)
    p.fields["box"] = box
    return p


def domains_for(p):
    """Domains with the centres their averaged bases reproduce: the particle (GIMP, CPDI1) or
    the CPDI2 domain's centroid (simplices and boxes, on every cell type)."""
    for dom in (GIMP(2), GIMP(3, deform=True), CPDI1()):
        yield dom, p.x
    for key in ("simplex", "box"):
        p.fields["corners"] = p.fields[key]  # set just before its use
        yield CPDI2(), domain_geometry(p.fields[key])[3]


def test_averaged_basis_partition_of_unity_and_linear_completeness(mesh_name):
    mesh = make_mesh(mesh_name)
    d = mesh.geometry.dim
    p = deformed_particles(mesh, mesh_name)
    assert p.num_global > 10
    V = fem.functionspace(mesh, ("Lagrange", 1))
    xd = V.tabulate_dof_coordinates()[:, :d]
    for dom, centre in domains_for(p):
        b = ParticleBasis(V, p, gradients=True, domain=dom)
        xs = b.update_ghosts(xd)  # with the coordinates of extra ghost dofs (remote samples)
        err = {
            "sum N": np.abs(b.values.sum(axis=1) - 1).max(initial=0.0),
            "sum grad N": np.abs(b.gradients.sum(axis=1)).max(initial=0.0),
            "sum N x": np.abs(np.einsum("nk,nkd->nd", b.values, xs[b.dofs]) - centre).max(initial=0.0),
            "sum x grad N": np.abs(np.einsum("nkd,nke->nde", xs[b.dofs], b.gradients) - np.eye(d)).max(initial=0.0),
        }
        err = {k: comm.allreduce(v, op=MPI.MAX) for k, v in err.items()}
        # Q1 on distorted cells is isoparametric: linear fields are in the space, so the
        # completeness holds there too (measured 1e-15)
        assert max(err.values()) < 1e-12, (mesh_name, dom, err)


@pytest.mark.parametrize("name", ["triangle", "quadrilateral", "unstructured-tetrahedron", "hexahedron"])
@pytest.mark.parametrize("mass", ["consistent", "lumped"])
def test_projection_with_averaged_bases(name, mass):
    """Consistent: a linear field is reproduced exactly (the normal equations of the averaged
    least-squares fit); lumped: constants. Mass and momentum are conserved in both. Particles
    fill the mesh (domains = their seeding sub-cells), so every dof is well supported."""
    mesh = make_mesh(name)
    d = mesh.geometry.dim
    p = fempm.create_particles(mesh, 4 if d < 3 else 8, density=2.0)
    if name in SIMPLICES:  # boxes well inside the particles' sub-simplices
        p.fields["lp"] = np.full((len(p), d), 0.1 * p.volume[0] ** (1 / d))
    else:  # the seeding sub-cells of the axis-aligned cells (2 per direction)
        cells = {"quadrilateral": (6, 5), "hexahedron": (3, 3, 2)}[name]
        p.fields["lp"] = np.broadcast_to(1.0 / np.array(cells) / 4, (len(p), d)).copy()
    V = fem.functionspace(mesh, ("Lagrange", 1, (d,)))
    lin = fem.Function(V)
    lin.interpolate(lambda x: np.vstack([1.0 + 2.0 * x[0] - x[1], *[0.5 - x[i] + 3 * x[0] for i in range(1, d)]]))
    f = fempm.interpolate(lin, p)  # the linear field at the particles = its domain average
    # CPDI2: the particles are their seeding sub-cells, which tile the mesh
    tiled = fempm.create_particles(mesh, 4 if d < 3 else 8, density=2.0, corners=True)
    np.testing.assert_allclose(tiled.x, p.x, atol=1e-14)
    p.fields["corners"] = tiled.fields["corners"]
    for dom in (GIMP(2), GIMP(3), CPDI1(), CPDI2()):
        proj = fempm.Projector(V, p, mass=mass, domain=dom)
        F = proj.project(f if mass == "consistent" else np.ones_like(f))
        target = lin.x.array if mass == "consistent" else 1.0
        err = np.abs(F.x.array - target).max()
        assert err < 1e-10, (name, dom, mass, err)
        G = proj.project(f)
        np.testing.assert_allclose(proj.grid_total(G), comm.allreduce(p.mass @ f), rtol=1e-12)


LARGE = {
    "quadrilateral": lambda: dm.create_unit_square(comm, 16, 16, dm.CellType.quadrilateral),
    "unstructured-triangle": lambda: unstructured_rectangle(comm, 1 / 16),
}


@pytest.mark.parametrize("name", sorted(LARGE))
def test_large_domains_across_ranks(name):
    """Boxes five cells wide: on 2 ranks their sample points reach cells that are neither owned
    nor ghost; the averaged basis still has the partition of unity and linear completeness to
    1e-12, and the consistent projection reproduces a linear field."""
    mesh = LARGE[name]()
    d = mesh.geometry.dim
    ell = 2.5 * comm.allreduce(cell_sizes(mesh).max(initial=0.0), op=MPI.MAX)
    p = fempm.create_particles(mesh, 4, density=1.0,
                               where=lambda x: np.all((x[:d] > 1.01 * ell) & (x[:d] < 1 - 1.01 * ell), axis=0))
    p.fields["lp"] = np.full((len(p), d), ell)
    V = fem.functionspace(mesh, ("Lagrange", 1))
    xd = V.tabulate_dof_coordinates()[:, :d]
    b = ParticleBasis(V, p, domain=GIMP(2))
    xs = b.update_ghosts(xd)  # coordinates of the extra ghost dofs too
    err = max(np.abs(b.values.sum(axis=1) - 1).max(initial=0.0),
              np.abs(np.einsum("nk,nkd->nd", b.values, xs[b.dofs]) - p.x).max(initial=0.0))
    assert comm.allreduce(err, op=MPI.MAX) < 1e-12
    if comm.size > 1:
        assert comm.allreduce(int(b.extended), op=MPI.MAX) == 1
    lin = fem.Function(V)
    lin.interpolate(lambda x: 1.0 + 2.0 * x[0] - x[1])
    # the domain averages of a linear field are its values at the particles
    proj = fempm.Projector(V, p, mass="consistent", basis=b)
    F = proj.project(fempm.interpolate(lin, p))
    act = proj.active[: len(lin.x.array)]
    err = np.abs(F.x.array - lin.x.array)[act].max(initial=0.0)
    # exact up to the solver: dofs at the edge of the support, barely touched by box corners,
    # make the matrix ill-conditioned, and KSP stops at rtol 1e-13 (measured 1.7e-8)
    assert comm.allreduce(err, op=MPI.MAX) < 1e-7


def test_domain_beyond_the_mesh_is_cut_off():
    """Boxes stretched 3x past the sides of the square: exact GIMP averages over the part inside,
    i.e. equals GIMP on the truncated boxes (lumped masses to round-off); the Gauss rule drops
    its points outside; both keep the partition of unity. Unknown domain names are errors."""
    from fempm.transfer import Projector

    mesh = make_mesh("quadrilateral")
    p = fempm.create_particles(mesh, 4, density=1.0)
    ell = 3.0 * half_widths(p)
    p.fields["F"] = np.broadcast_to(np.eye(2) * 3.0, (len(p), 2, 2)).copy()
    V = fem.functionspace(mesh, ("Lagrange", 1))
    for dom in (GIMP(None, deform=True), GIMP(2, deform=True)):
        basis = ParticleBasis(V, p, domain=dom)
        assert np.abs(basis.values.sum(axis=1) - 1).max(initial=0) < 1e-12
    m_cut = Projector(V, p, mass="lumped", domain=GIMP(None, deform=True)).lumped_masses()
    lo, hi = np.maximum(p.x - ell, 0.0), np.minimum(p.x + ell, 1.0)
    q = fempm.Particles(mesh, (lo + hi) / 2, p.mass, p.volume, fields={"lp": (hi - lo) / 2})
    m_trunc = Projector(V, q, mass="lumped", domain=GIMP(None)).lumped_masses()
    assert np.abs(m_cut - m_trunc).max() < 1e-14 * m_cut.max()
    with pytest.raises(ValueError, match="unknown option domain"):
        make_domain("bspline")


def test_step_options_build_the_domains():
    from fempm.stepping import StepOptions

    assert StepOptions(domain="gimp", gimp_order=3, gimp_deform=True).particle_domain == GIMP(3, deform=True)
    assert StepOptions(domain="gimp").particle_domain == GIMP(None, deform=False)  # exact by default
    assert StepOptions(domain="cpgimp").particle_domain == GIMP(None, deform=True, name="cpgimp")
    assert StepOptions(domain="ugimp", gimp_deform=True).particle_domain == GIMP(None, deform=False, name="ugimp")
    assert StepOptions(domain="cpdi1").particle_domain == CPDI1()
    assert StepOptions(domain="cpdi2").particle_domain == CPDI2()
    with pytest.raises(ValueError, match="position='particle' would detach"):
        StepOptions(domain="cpdi2", position="particle")


def test_cpdi2_corner_errors():
    """Missing, misshapen, degenerate and twisted corner sets, and jittered corner seeding, are
    errors that name the problem."""
    mesh = make_mesh("triangle")
    p = fempm.create_particles(mesh, 1, density=1.0)
    with pytest.raises(ValueError, match="CPDI2 needs particle corners"):
        CPDI2().samples(p)
    with pytest.raises(ValueError, match="jitter=0"):
        fempm.create_particles(mesh, 1, jitter=0.3, corners=True)
    x = np.zeros((1, 2))
    with pytest.raises(ValueError, match="got 5 corners in 2D"):
        domain_geometry(np.zeros((1, 5, 2)))
    with pytest.raises(ValueError, match="degenerate or twisted"):
        domain_geometry(np.array([[[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]]))  # collinear triangle
    twisted = box_corners(x, np.ones((1, 2)))[:, [0, 1, 3, 2]]  # a bow tie
    with pytest.raises(ValueError, match="degenerate or twisted"):
        domain_geometry(twisted)
    mirrored = box_corners(x, np.ones((1, 2)))[:, [1, 0, 3, 2]]  # reflected order: a valid square
    np.testing.assert_allclose(domain_geometry(mirrored)[2], [4.0], rtol=1e-14)
