"""Singular consistent mass detected from the particles' span (fempm.transfer.mass_span), and
consistent-mass runs that do not depend on the number of ranks."""

import dolfinx.fem as fem
import dolfinx.mesh as dm
import numpy as np
import pytest
from mpi4py import MPI

import fempm
from fempm.scene import run
from fempm.scenes import two_disks

pytestmark = [pytest.mark.parallel,  # also under mpiexec -n 2 (scripts/run-tests)
              pytest.mark.xdist_group("test_mass_span")]  # one worker computes its module fixtures

comm = MPI.COMM_WORLD


@pytest.fixture(scope="module")
def V():
    mesh = dm.create_unit_square(comm, 4, 4, dm.CellType.quadrilateral)
    return fem.functionspace(mesh, ("Lagrange", 1))


def _particles(V, x):
    return fempm.Particles(V.mesh, x if comm.rank == 0 else np.zeros((0, 2)), 1.0, 1.0)


@pytest.mark.parametrize("layout", ["coincident", "collinear", "collinear-diagonal"])
def test_coincident_and_collinear_particles_are_singular(V, layout):
    t = np.linspace(0.01, 0.99, 400)
    x = {"coincident": np.tile([[0.3, 0.4]], (400, 1)), "collinear": np.c_[t, 0.37 + 0 * t],
         "collinear-diagonal": np.c_[t, t]}[layout]
    p = _particles(V, x)  # 400 particles: the count test alone passes
    with pytest.raises(fempm.SingularMassError, match="singular"):
        fempm.project(V, p, np.ones(len(p)), mass="consistent")


def test_spanning_particles_are_not_singular(V):
    p = fempm.create_particles(V.mesh, 4, jitter=0.5, seed=1)
    F = fempm.project(V, p, np.ones(len(p)), mass="consistent")
    assert comm.allreduce(np.abs(F.x.array - 1).max(), op=MPI.MAX) < 1e-12
    # an interior cell of collinear particles among spanning ones: its dofs are fixed by the neighbours
    inside = (np.abs(p.x - 0.375) < 0.125).all(axis=1)
    t = np.linspace(0.26, 0.49, 30)
    x = np.concatenate([p.x[~inside], np.c_[t, np.full_like(t, 0.3)] if comm.rank == 0 else np.zeros((0, 2))])
    q = fempm.Particles(V.mesh, x, 1.0, 1.0)
    lin = fem.Function(V)
    lin.interpolate(lambda y: 1 + y[0] - 2 * y[1])
    F = fempm.project(V, q, fempm.interpolate(lin, q), mass="consistent")
    assert comm.allreduce(np.abs(F.x.array - lin.x.array).max(), op=MPI.MAX) < 1e-10


def test_one_particle_per_triangle_is_singular():
    mesh = dm.create_unit_square(comm, 6, 6)
    p = fempm.create_particles(mesh, 1)  # 72 particles for 49 dofs: the count test passes
    with pytest.raises(fempm.SingularMassError, match="direction"):
        fempm.project(fem.functionspace(mesh, ("Lagrange", 1)), p, np.ones(len(p)), mass="consistent")


def test_consistent_run_is_independent_of_the_number_of_ranks():
    """The same consistent-mass two-disk run on all ranks and on each rank alone (serial)."""
    def energies(c):
        s = run(two_disks(cells=12, t_end=2.0, mass="consistent", frames=0, comm=c), None, progress=False)
        return np.array([[r["dt"], r["total"], r["kinetic"], r["momentum_x"]] for r in s["history"][1:]])

    parallel = energies(comm)
    serial = energies(MPI.COMM_SELF)
    assert parallel.shape == serial.shape
    assert np.abs(parallel - serial).max() < 1e-10 * np.abs(serial).max()


@pytest.mark.parametrize("cell", [dm.CellType.triangle, dm.CellType.quadrilateral])
def test_compiled_span_test_equals_the_rounds_of_eigenvalue_tests(monkeypatch, cell):
    """The worklist kernel with pivot bounds (fempm.kernels.consistent.propagate) reaches the
    same determined dofs as rounds of eigvalsh tests, on sparse random particles (many cells
    span nothing, some are determined only through their neighbours) and collinear ones."""
    from fempm.transfer import mass_span
    from fempm.transfer import cell_blocks

    mesh = dm.create_unit_square(comm, 9, 7, cell)
    V1 = fem.functionspace(mesh, ("Lagrange", 1))
    rng = np.random.default_rng(4)
    t = rng.random(60)
    x = np.r_[rng.random((90, 2)), np.c_[t, 0.5 + 0 * t]] if comm.rank == 0 else np.zeros((0, 2))
    p = fempm.Particles(mesh, x, 1.0, 1.0)
    basis = fempm.ParticleBasis(V1, p)
    blocks = cell_blocks(basis, p.mass)
    n = V1.dofmap.index_map.size_local + V1.dofmap.index_map.num_ghosts
    active = fempm.transfer.p2g(basis, p.mass)[:, 0] > 0
    results = []
    for compiled in (True, False):
        monkeypatch.setattr(mass_span, "AVAILABLE", compiled)
        results.append(mass_span.singular_dofs(V1.dofmap.index_map, blocks, active, np.zeros(n, bool)))
    assert results[0] == results[1]
    assert results[0][1] > 0  # some dofs are left to the dense test


def test_eigenvalue_bounds_decide_like_eigvalsh():
    from fempm.transfer.mass_span import _smallest_above

    rng = np.random.default_rng(1)
    for k in (2, 3, 4, 8):
        A = rng.standard_normal((3000, k, 6))
        A[:1000, :, 1:] *= 1e-6 * rng.random((1000, 1, 1))  # nearly rank 1
        A[1000:1500, :, 2:] = 0.0  # rank 2
        B = A @ A.transpose(0, 2, 1)
        d = np.sqrt(np.einsum("nii->ni", B))
        B = B / d[:, :, None] / d[:, None, :]
        ref = np.linalg.eigvalsh(B)[:, 0] > 1e-10
        assert np.array_equal(_smallest_above(B, 1e-10), ref)
        assert 0 < ref.sum() < len(ref) or k == 8


@pytest.mark.parametrize("n", [16, 32])
def test_dofs_shared_by_cells_are_tested_sparsely_at_any_size(n):
    """P2 on triangles with 4 lattice particles each: no cell's particles determine its 6 dofs,
    and the matrix over the dofs the cells share has 2 null directions. At 16 x 16 (1089 dofs)
    the dense test found them too; at 32 x 32 (4225 dofs) it was skipped with a warning and the
    projection went on with a singular matrix. The sparse test (MUMPS' null pivots) finds them
    at both sizes."""
    from fempm.transfer import SingularMassError

    mesh = dm.create_unit_square(MPI.COMM_WORLD, n, n)
    p = fempm.create_particles(mesh, 4, density=1.0)
    V = fem.functionspace(mesh, ("Lagrange", 2))
    with pytest.raises(SingularMassError, match=rf"no unique value on 2 direction\(s\) of the {(2 * n + 1) ** 2} dofs"):
        fempm.project(V, p, lambda x: x[0] ** 2, mass="consistent")
