"""Exact GIMP: integrals of the basis over boxes cut by the cells (fempm.transfer.box_average), the
averaged basis built from them, truncation at the mesh boundary; serial and on 2 ranks."""

import dolfinx
import dolfinx.mesh as dm
import numpy as np
import pytest
from conftest import make_mesh
from mpi4py import MPI

from fempm.transfer.basis import ParticleBasis
from fempm.transfer.box_average import BoxIntegrator, CellBins, clip_simplices
from fempm.transfer.domains import GIMP, make_domain
from fempm.particles import Particles
from fempm.particles.seeding import create_particles


#: meshes whose cells map affinely (or as axis-aligned boxes): the box integrals are exact
EXACT = ["interval", "triangle", "quadrilateral", "tetrahedron", "hexahedron", "unstructured-tetrahedron"]


def integrator(V):
    from fempm.meshes.geometry import CellGeometry

    mesh = V.mesh
    g = CellGeometry(mesh)
    owned = mesh.topology.index_map(mesh.topology.dim).size_local
    return BoxIntegrator(g, V.element.basix_element, V.dofmap.list, CellBins(g, np.arange(owned, dtype=np.int32)))


def box_moments(lo, hi):
    """Exact integrals of 1, x_a and x_a x_b over boxes: (m,), (m, d), (m, d, d)."""
    vol = np.prod(hi - lo, axis=1)
    m1 = (hi**2 - lo**2) / 2 / (hi - lo) * vol[:, None]
    mean = m1 / vol[:, None]
    sq = (hi**3 - lo**3) / 3 / (hi - lo)  # mean of x_a^2
    m2 = np.einsum("ma,mb->mab", mean, mean) * vol[:, None, None]
    d = lo.shape[1]
    m2[:, np.arange(d), np.arange(d)] = sq * vol[:, None]
    return vol, m1, m2


def summed(rows, values, m):
    return np.bincount(rows.box, weights=rows.N * values, minlength=m)


@pytest.mark.parametrize("name", EXACT)
@pytest.mark.parametrize("degree", [1, 2])
@pytest.mark.parallel
def test_box_integrals_are_exact(name, degree):
    """Sum_i f(x_i) int_box N_i = int_box f for every f the space reproduces: 1, x, and for
    degree 2 the quadratic monomials; int grad N_i x_i^T = |box| I. Boxes inside the mesh,
    straddling cells and grid lines; the owned parts summed over ranks."""
    comm = MPI.COMM_WORLD
    mesh = make_mesh(name, comm)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", degree))
    integ = integrator(V)
    d = mesh.geometry.dim
    rng = np.random.default_rng(0)
    c = rng.uniform(0.2, 0.8, (40, d))
    ell = rng.uniform(0.03, 0.18, (40, d))
    lo, hi = c - ell, c + ell
    r = integ.integrals(lo, hi, True)
    xd = V.tabulate_dof_coordinates()[:, :d]
    m = len(lo)
    vol, m1, m2 = box_moments(lo, hi)
    got_vol = comm.allreduce(r.volume)
    assert np.abs(got_vol - vol).max() <= 1e-13 * vol.max()
    assert np.abs(comm.allreduce(summed(r, 1.0, m)) - vol).max() <= 1e-13 * vol.max()
    for a in range(d):
        assert np.abs(comm.allreduce(summed(r, xd[r.dofs, a], m)) - m1[:, a]).max() <= 1e-13
        for b in range(d):
            G = comm.allreduce(np.bincount(r.box, weights=r.dN[:, b] * xd[r.dofs, a], minlength=m))
            assert np.abs(G - (a == b) * vol).max() <= 1e-12 * vol.max()
            if degree == 2 and (a == b or name not in ("interval",)):
                q = comm.allreduce(summed(r, xd[r.dofs, a] * xd[r.dofs, b], m))
                assert np.abs(q - m2[:, a, b]).max() <= 1e-13, (a, b)


@pytest.mark.parallel
def test_clipped_simplices_keep_the_volume_inside_the_box():
    """A tetrahedron clipped by boxes: the pieces' volumes equal a fine Monte Carlo estimate of
    the intersection (and, for a box holding the whole tetrahedron, the tetrahedron)."""
    rng = np.random.default_rng(1)
    T = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]])
    P, parent = clip_simplices(T, np.array([[-1.0, -1, -1]]), np.array([[2.0, 2, 2]]))
    assert np.isclose(np.abs(np.linalg.det(P[:, 1:] - P[:, :1])).sum() / 6, 1 / 6)
    lo, hi = np.array([[0.1, -0.2, 0.05]]), np.array([[0.7, 0.45, 0.5]])
    P, parent = clip_simplices(T, lo, hi)
    vol = np.abs(np.linalg.det(P[:, 1:] - P[:, :1])).sum() / 6
    y = rng.uniform(lo, hi, (400000, 3))
    inside = (y >= 0).all(axis=1) & (y.sum(axis=1) <= 1)
    mc = inside.mean() * np.prod(hi - lo)
    assert abs(vol - mc) < 4 * np.sqrt(mc * np.prod(hi - lo) / len(y))
    assert np.all((P >= lo - 1e-15) & (P <= hi + 1e-15))


@pytest.mark.parallel
def test_exact_gimp_is_the_closed_form_1d_gimp_function():
    """1D linear hats, box half-width l <= h/2: <N_0>_p equals Bardenhagen and Kober's GIMP
    function of the distance |x| to the node (where the Gauss rule is not exact)."""
    comm = MPI.COMM_WORLD
    h = 0.1
    mesh = dm.create_interval(comm, 10, [0.0, 1.0])
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    rng = np.random.default_rng(2)
    x = rng.uniform(0.2, 0.8, 60) if comm.rank == 0 else np.zeros(0)
    ell = rng.uniform(0.005, 0.05, 60) if comm.rank == 0 else np.zeros(0)
    p = Particles(mesh, x[:, None], 1.0, 2 * ell, fields={"lp": ell[:, None]})
    basis = ParticleBasis(V, p, domain=GIMP(), gradients=True)
    node = np.rint(p.x[:, 0] / h) * h  # the nearest node
    xd = V.tabulate_dof_coordinates()[:, 0]
    S = np.where(np.isclose(xd[basis.dofs], node[:, None]), basis.values, 0.0).sum(axis=1)
    r, lp = np.abs(p.x[:, 0] - node), p.fields["lp"][:, 0]
    expected = np.where(r < lp, 1 - (r**2 + lp**2) / (2 * h * lp), 1 - r / h)
    assert np.abs(S - expected).max() < 1e-13
    gauss = ParticleBasis(V, p, domain=GIMP(order=2))
    Sg = np.where(np.isclose(xd[gauss.dofs], node[:, None]), gauss.values, 0.0).sum(axis=1)
    straddle = r < lp
    assert comm.allreduce(np.abs(Sg - expected)[straddle].max(initial=0.0), op=MPI.MAX) > 1e-4


def _stretch(p, domain: str) -> None:
    """A shear-stretch F on every particle (CPDI2: its corners pushed out about the particle)."""
    F = np.array([[1.3, 0.2], [0.1, 0.9]])
    p.fields["F"] = np.broadcast_to(F, (len(p), 2, 2)).copy()
    if domain == "cpdi2":
        c = p.fields["corners"]
        p.fields["corners"] = p.x[:, None, :] + (c - p.x[:, None, :]) @ F.T


@pytest.mark.parametrize("cell", ["triangle", "quadrilateral"])
@pytest.mark.parametrize("domain", ["point", "gimp", "ugimp", "cpgimp", "cpdi1", "cpdi2"])
@pytest.mark.parallel
def test_domains_in_the_boundary_cells_keep_unity_and_conservation(cell, domain):
    """Particles fill every cell of the unit square, domains reach past its sides (stretched by
    a shear F): the part beyond is cut off, the averaged basis keeps the partition of unity and
    sum_i <grad N_i> = 0, lumped and consistent projections conserve mass and momentum."""
    from fempm.transfer import Projector

    comm = MPI.COMM_WORLD
    mesh = dm.create_unit_square(comm, 6, 6, getattr(dm.CellType, cell))
    p = create_particles(mesh, 4, density=2.0, corners=domain == "cpdi2")
    _stretch(p, domain)
    dom = make_domain(domain)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    basis = ParticleBasis(V, p, gradients=True, domain=dom)
    assert np.abs(basis.values.sum(axis=1) - 1).max(initial=0) < 1e-12
    assert np.abs(basis.gradients.sum(axis=1)).max(initial=0) < 1e-10
    assert np.all(basis.values >= -1e-14)
    v = np.column_stack([np.sin(3 * p.x[:, 0]), p.x[:, 1] ** 2])
    for mass in ("lumped", "consistent"):
        proj = Projector(dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,))), p, mass=mass, domain=dom)
        u = proj.project(v)
        total = proj.grid_total(u)
        assert np.allclose(total, comm.allreduce(p.mass @ v), rtol=1e-10, atol=1e-12)
    # the averaged basis does not depend on the partition: lumped masses by dof position = serial
    assert np.allclose(_lumped_by_position(mesh, p, dom), _lumped_by_position(*_serial_body(cell, domain), dom),
                       rtol=1e-12, atol=1e-14)


def _lumped_by_position(mesh, p, dom) -> np.ndarray:
    """Lumped P1 masses of all owned dofs over the ranks, ordered by dof position."""
    from fempm.transfer import Projector

    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    n = V.dofmap.index_map.size_local
    m = Projector(V, p, mass="lumped", domain=dom).lumped_masses()[:n]
    xy = V.tabulate_dof_coordinates()[:n, :2]
    rows = np.concatenate(mesh.comm.allgather(np.column_stack([np.round(xy, 12), m])))
    return rows[np.lexsort((rows[:, 1], rows[:, 0]))][:, 2]


def _serial_body(cell: str, domain: str):
    """The same body as in the test above, on one rank."""
    mesh = dm.create_unit_square(MPI.COMM_SELF, 6, 6, getattr(dm.CellType, cell))
    p = create_particles(mesh, 4, density=2.0, corners=domain == "cpdi2")
    _stretch(p, domain)
    return mesh, p


#: one mesh for each domain in the default run, the other in make test-all
LOOP_DEFAULT = (("point", "structured"), ("gimp", "triangles"), ("ugimp", "structured"), ("cpgimp", "triangles"),
                ("cpdi1", "triangles"), ("cpdi2", "triangles"))


@pytest.mark.parametrize(("domain", "mesh"), [
    pytest.param(d, m, marks=() if (d, m) in LOOP_DEFAULT else pytest.mark.slow)
    for d in ["point", "gimp", "ugimp", "cpgimp", "cpdi1", "cpdi2"] for m in ["structured", "triangles"]])
@pytest.mark.parallel(only=("cpdi1-triangles", "ugimp-structured"))
def test_every_domain_runs_the_loop_in_the_boundary_cells(mesh, domain):
    """The 2D axis-aligned solution fills the unit square (slip walls) with particles in every
    boundary cell: each domain type runs a fifth of a period, with errors a few percent of the
    amplitude, the same on any number of ranks."""
    from fempm.verification import manufactured as mf
    from fempm.verification.errors import ErrorHistory
    from fempm.scene import run
    from fempm.scenes.manufactured import manufactured_scene

    problem = mf.axis_aligned(0.05, 2)
    scene = manufactured_scene(problem, 8, mesh=mesh, domain=domain, t_end=0.004, dt=5e-5)
    hist = ErrorHistory(problem, scene.particles)
    summary = run(scene, None, progress=False, callback=hist)
    assert summary["steps"] == 80
    assert hist.worst["max"] < 0.2 * problem.A, hist.worst
    if MPI.COMM_WORLD.size == 1:
        return  # the run above is the serial one
    serial = _serial_final_errors(mesh, domain)
    assert np.isclose(hist.rows[-1]["l2"], serial, rtol=1e-9, atol=1e-14)


def _serial_final_errors(mesh: str, domain: str) -> float:
    from fempm.verification import manufactured as mf
    from fempm.verification.errors import particle_errors
    from fempm.scene import run
    from fempm.scenes.manufactured import manufactured_scene

    problem = mf.axis_aligned(0.05, 2)
    scene = manufactured_scene(problem, 8, mesh=mesh, domain=domain, t_end=0.004, dt=5e-5, comm=MPI.COMM_SELF)
    run(scene, None, progress=False)
    return particle_errors(scene.particles, problem, 0.004)["l2"]
