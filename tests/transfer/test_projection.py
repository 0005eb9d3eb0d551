"""Galerkin projection: exact reproduction of FE fields (consistent), constants (lumped),
conservation, errors, and the parallel result against the serial one."""

import basix
import basix.ufl
import dolfinx.fem as fem
import fempm
import numpy as np
import pytest
from conftest import make_mesh, ppc_for
from mpi4py import MPI

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD


def random_function(V, seed=0):
    u = fem.Function(V)
    imap = V.dofmap.index_map
    bs = V.dofmap.index_map_bs
    g = imap.local_to_global(np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32))
    # a value per global dof, independent of the partition
    vals = np.sin(1.0 + 12.9898 * (g[:, None] * bs + np.arange(bs)) + seed) * 43758.5453
    u.x.array[:] = (vals - np.floor(vals)).ravel()
    return u


@pytest.mark.parametrize("degree", [1, 2])
def test_consistent_reproduces_fe_fields(mesh_name, degree):
    mesh = make_mesh(mesh_name)
    p = fempm.create_particles(mesh, ppc_for(mesh, degree), density=2.5, jitter=0.6, seed=9)
    for shape in [(), (mesh.geometry.dim,)]:
        V = fem.functionspace(mesh, ("Lagrange", degree, shape))
        u = random_function(V)
        F = fempm.project(V, p, fempm.interpolate(u, p), mass="consistent")
        err = comm.allreduce(np.abs(F.x.array - u.x.array).max(initial=0.0), op=MPI.MAX)
        assert err < 1e-10, f"{mesh_name} P{degree} {shape}: max dof error {err:.2e}"


@pytest.mark.parametrize("name", ["triangle", "unstructured-quadrilateral", "tetrahedron", "distorted-hexahedron"])
def test_lumped_reproduces_constants_not_linears(name):
    mesh = make_mesh(name)
    p = fempm.create_particles(mesh, 2 ** mesh.topology.dim, jitter=0.8, seed=2)
    V = fem.functionspace(mesh, ("Lagrange", 1))
    F = fempm.project(V, p, np.full(len(p), 3.7), mass="lumped")
    assert comm.allreduce(np.abs(F.x.array - 3.7).max(), op=MPI.MAX) < 1e-12
    lin = fem.Function(V)
    lin.interpolate(lambda x: 1.0 + 2.0 * x[0] - x[1])
    FL = fempm.project(V, p, fempm.interpolate(lin, p), mass="lumped")
    err_lumped = comm.allreduce(np.abs(FL.x.array - lin.x.array).max(), op=MPI.MAX)
    FC = fempm.project(V, p, fempm.interpolate(lin, p), mass="consistent")
    err_consistent = comm.allreduce(np.abs(FC.x.array - lin.x.array).max(), op=MPI.MAX)
    assert err_lumped > 1e-2 and err_consistent < 1e-10


def test_lumped_bernstein_reproduces_constants():
    mesh = make_mesh("unstructured-triangle")
    p = fempm.create_particles(mesh, 9, jitter=0.5, seed=1)
    el = basix.ufl.element("P", "triangle", 2, lagrange_variant=basix.LagrangeVariant.bernstein)
    F = fempm.project(fem.functionspace(mesh, el), p, np.full(len(p), -2.0), mass="lumped")
    assert comm.allreduce(np.abs(F.x.array + 2.0).max(), op=MPI.MAX) < 1e-12


def test_lumped_p2_lagrange_is_refused():
    mesh = make_mesh("triangle")
    p = fempm.create_particles(mesh, 9)
    with pytest.raises(ValueError, match="non-negative basis"):
        fempm.project(fem.functionspace(mesh, ("Lagrange", 2)), p, np.ones(len(p)), mass="lumped")
    with pytest.raises(ValueError, match="unknown option mass='diagonal'"):
        fempm.project(fem.functionspace(mesh, ("Lagrange", 1)), p, np.ones(len(p)), mass="diagonal")


@pytest.mark.parametrize("mass,degree", [("lumped", 1), ("consistent", 1), ("consistent", 2)])
def test_mass_and_momentum_conserved(mass, degree):
    mesh = make_mesh("unstructured-triangle")
    p = fempm.create_particles(mesh, 9, density=1000.0, jitter=0.9, seed=5)
    V = fem.functionspace(mesh, ("Lagrange", degree, (2,)))
    v = np.column_stack([np.sin(7 * p.x[:, 0]) + p.x[:, 1] ** 3, np.cos(5 * p.x[:, 1])])
    proj = fempm.Projector(V, p, mass=mass)
    F = proj.project(v)
    momentum = comm.allreduce(p.mass @ v)
    np.testing.assert_allclose(proj.grid_total(F), momentum, rtol=1e-13)
    one = fem.Function(V)
    one.x.array[:] = 1.0
    np.testing.assert_allclose(proj.grid_total(one), comm.allreduce(p.mass.sum()), rtol=1e-13)


def test_partial_lumping_keeps_conservation_and_constants():
    """Lumping the weakly supported dofs (a disk's rim) keeps row sums: mass and momentum are
    conserved and constants reproduced to round-off, while interior linear fields stay exact."""
    mesh = make_mesh("unstructured-triangle")
    p = fempm.create_particles(mesh, 4, density=1000.0, where=lambda x: np.hypot(x[0] - 0.5, x[1] - 0.5) < 0.37)
    V = fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    full = fempm.Projector(V, p, mass="consistent")
    part = fempm.Projector(V, p, mass="consistent", lump_below=0.2)
    m = part.lumped_masses()
    lumped = comm.allreduce(int(np.count_nonzero(m[: part.num_owned] < 0.2 * comm.allreduce(m.max(), op=MPI.MAX))))
    assert lumped > 10  # the rim is lumped
    np.testing.assert_allclose(part.row_mass, full.row_mass, rtol=1e-12, atol=1e-12 * full.row_mass.max())
    v = np.column_stack([np.sin(7 * p.x[:, 0]), np.cos(5 * p.x[:, 1])])
    F = part.project(v)
    np.testing.assert_allclose(part.grid_total(F), comm.allreduce(p.mass @ v), rtol=1e-13)
    one = part.project(np.ones((len(p), 2)))
    act = np.repeat(part.active, 2)
    assert comm.allreduce(np.abs(one.x.array[act] - 1.0).max(initial=0.0), op=MPI.MAX) < 1e-12


def test_unsupported_dofs_are_excluded_and_reported():
    """Particles only in the left half: the right half's dofs are inactive and set to 0."""
    mesh = make_mesh("triangle")
    rng = np.random.default_rng(0)
    x = rng.random((600, 2)) * [0.45, 1.0]
    p = fempm.Particles(mesh, x if comm.rank == 0 else np.zeros((0, 2)), 1.0, 1.0)
    V = fem.functionspace(mesh, ("Lagrange", 1))
    proj = fempm.Projector(V, p)
    lin = fem.Function(V)
    lin.interpolate(lambda x: 2.0 - x[1])
    F = proj.project(fempm.interpolate(lin, p))
    xd = V.tabulate_dof_coordinates()[:, 0]
    assert proj.num_inactive == 3 * 6  # vertex columns x = 4/6, 5/6, 1 of the 6x5 mesh
    assert np.all(F.x.array[xd > 0.6] == 0.0)
    err = np.abs(F.x.array - lin.x.array)[proj.active].max(initial=0.0)
    assert comm.allreduce(err, op=MPI.MAX) < 1e-10


def test_too_few_particles_for_the_space_is_reported():
    mesh = make_mesh("quadrilateral")  # Q2 on 6x5 cells: 143 dofs, 4 particles per cell: 120
    p = fempm.create_particles(mesh, 4)
    with pytest.raises(fempm.SingularMassError, match="120 particles support 143 coupled dofs"):
        fempm.project(fem.functionspace(mesh, ("Lagrange", 2)), p, np.ones(len(p)))


@pytest.mark.parametrize("name,degree,mass", [
    ("unstructured-triangle", 2, "consistent"),
    ("unstructured-triangle", 1, "lumped"),
    ("distorted-hexahedron", 1, "consistent"),
    ("unstructured-tetrahedron", 1, "lumped"),
])
def test_parallel_equals_serial(name, degree, mass):
    """Same particles on a distributed mesh and on a serial copy: same projected field."""
    serial_mesh = make_mesh(name, MPI.COMM_SELF)
    ps = fempm.create_particles(serial_mesh, ppc_for(serial_mesh, degree), jitter=0.7, seed=8)
    f = np.sin(4 * ps.x[:, 0]) * np.cos(3 * ps.x[:, 1]) + ps.x[:, -1] ** 2
    Fs = fempm.project(fem.functionspace(serial_mesh, ("Lagrange", degree)), ps, f, mass=mass)
    mesh = make_mesh(name, comm)
    mine = slice(None) if comm.rank == 0 else slice(0, 0)
    pw = fempm.Particles(mesh, ps.x[mine], ps.mass[mine], ps.volume[mine], ids=ps.ids[mine], fields={"f": f[mine]})
    Fw = fempm.project(fem.functionspace(mesh, ("Lagrange", degree)), pw, pw.fields["f"], mass=mass)
    # compare the two fields at the particles (matched by id)
    vs = fempm.interpolate(Fs, ps)
    vw = fempm.interpolate(Fw, pw)
    order = np.argsort(ps.ids)
    ref = vs[order][np.searchsorted(ps.ids[order], pw.ids)]
    diff = comm.allreduce(np.abs(vw - ref).max(initial=0.0), op=MPI.MAX)
    assert pw.num_global == len(ps)
    assert diff < 1e-10


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_per_volume_fields_are_volume_weighted(mass):
    """Stress-like (per-volume) data across a density jump (rho = 1 | 10): the volume-weighted
    map (the density-ratio kernel) conserves the integral sum_p V_p sigma_p; the
    mass-weighted one does not. Both reproduce constants; the consistent one linear fields."""
    import dolfinx.mesh as dm

    mesh = dm.create_unit_square(comm, 8, 8, dm.CellType.quadrilateral)
    p = fempm.create_particles(mesh, 4, density=lambda x: np.where(x[:, 0] < 0.5, 1.0, 10.0))
    V = fem.functionspace(mesh, ("Lagrange", 1, (2, 2)))
    sigma = np.zeros((len(p), 2, 2))
    sigma[:, 0, 0] = 1.0 + 2.0 * p.x[:, 0]
    sigma[:, 1, 1] = -3.0 * p.x[:, 1] + np.sin(7.0 * p.x[:, 0])  # not in the space
    sigma[:, 0, 1] = sigma[:, 1, 0] = 0.5
    total = comm.allreduce(p.volume @ sigma.reshape(-1, 4))
    by_volume = fempm.Projector(V, p, mass=mass, weight="volume")
    by_mass = fempm.Projector(V, p, mass=mass)
    S_v, S_m = by_volume.project(sigma), by_mass.project(sigma)
    np.testing.assert_allclose(by_volume.grid_total(S_v), total, rtol=1e-12)
    # measured: 3.0e-2 (lumped), 5.8e-4 (consistent) of the largest component
    assert np.abs(by_volume.grid_total(S_m) - total).max() > 2e-4 * np.abs(total).max()
    one = by_volume.project(np.broadcast_to(np.eye(2), (len(p), 2, 2)).copy())
    assert np.abs(one.x.array - np.tile(np.eye(2).ravel(), len(one.x.array) // 4)).max() < 1e-10
    if mass == "consistent":
        ref = fem.Function(V)
        ref.interpolate(lambda x: np.vstack([1 + 2 * x[0], 0.5 + 0 * x[0], 0.5 + 0 * x[0], -3 * x[1]]))
        linear = np.arange(len(ref.x.array)) % 4 != 3  # the components that are linear
        assert np.abs(S_v.x.array - ref.x.array)[linear].max() < 1e-10
    with pytest.raises(ValueError, match="unknown option weight"):
        fempm.Projector(V, p, weight="density")


def test_component_constraints_give_the_constrained_least_squares_fit():
    """exclude_components: component 0 held at 0 on x = 0 and x = 1 (slip walls normal to x),
    component 1 on y = 0. The consistent result is the constrained fit: those components vanish
    and the residual sum_p M_p (F(x_p) - f_p) N_j(x_p) is zero for every free (dof, component)."""
    from fempm.transfer.basis import ParticleBasis
    from fempm.boundary import locate_dofs
    from fempm.transfer import p2g

    mesh = make_mesh("triangle")
    p = fempm.create_particles(mesh, 4, density=2.0, jitter=0.5, seed=3)
    V = fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    walls_x = locate_dofs(V, lambda x: np.isclose(x[0], 0.0) | np.isclose(x[0], 1.0))
    walls_y = locate_dofs(V, lambda x: np.isclose(x[1], 0.0))
    f = np.column_stack([np.cos(3 * p.x[:, 1]) + p.x[:, 0], np.exp(p.x[:, 0]) * (1 + p.x[:, 1])])
    proj = fempm.Projector(V, p, mass="consistent", exclude_components=[walls_x, walls_y])
    F = proj.project(f).x.array.reshape(-1, 2)
    assert np.abs(F[walls_x, 0]).max(initial=0) == 0 and np.abs(F[walls_y, 1]).max(initial=0) == 0
    assert np.abs(F[walls_x, 1]).max(initial=0) > 0.1  # the other component is free
    basis = ParticleBasis(V, p)
    residual = p2g(basis, p.mass[:, None] * (basis.gather(F) - f))
    free = np.ones(residual.shape, dtype=bool)
    free[walls_x, 0] = free[walls_y, 1] = False
    n = V.dofmap.index_map.size_local
    assert comm.allreduce(np.abs(residual[:n][free[:n]]).max(initial=0.0), op=MPI.MAX) < 1e-10
    assert comm.allreduce(np.abs(residual[:n][~free[:n]]).max(initial=0.0), op=MPI.MAX) > 1e-3
