"""A mesh distributed by particles (fempm.particles.partition): balanced counts, the same mesh, the same run."""

import dolfinx
import fempm
import numpy as np
import pytest
import ufl
from fempm.boundary import slip
from fempm.materials import NeoHookean
from fempm.particles.partition import particle_balanced, rcb_parts
from fempm.stepping import ExplicitSolver, StepOptions
from mpi4py import MPI

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD


def _blob(n):
    """``n`` points in a corner of the unit square, all given on rank 0."""
    x = 0.05 + 0.35 * np.random.default_rng(3).random((n, 2))
    return x if comm.rank == 0 else np.zeros((0, 2))


@pytest.mark.parametrize("parts", [2, 3, 5])
def test_rcb_splits_the_weight_evenly(parts):
    """Points only (no cell weight): each part gets 1/parts of the points, to one point."""
    x = _blob(3000)
    part = rcb_parts(comm, np.zeros((0, 2)), x, parts, 1.0)
    counts = np.bincount(part, minlength=parts)
    counts = comm.allreduce(counts)
    assert counts.sum() == 3000
    assert counts.max() - counts.min() <= parts


@pytest.mark.parametrize("cell_type", [dolfinx.mesh.CellType.triangle, dolfinx.mesh.CellType.quadrilateral])
def test_particles_are_balanced_and_the_mesh_is_the_same(cell_type):
    mesh = dolfinx.mesh.create_unit_square(comm, 48, 48, cell_type)
    x = _blob(6000)
    balanced = particle_balanced(mesh, x, cell_weight=0.0)
    p = fempm.Particles(balanced, x, 1.0, 1.0)
    counts = np.array(comm.allgather(len(p.x)))
    assert counts.sum() == 6000
    # a cut through cells: at most the particles of the cells along it (24 cells of ~10)
    assert counts.max() - counts.min() <= 0.1 * 6000 / comm.size
    imap = balanced.topology.index_map(2)
    assert imap.size_global == mesh.topology.index_map(2).size_global
    area = comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(1.0 * ufl.dx(domain=balanced))))
    assert abs(area - 1.0) < 1e-12
    xx = ufl.SpatialCoordinate(balanced)
    moment = comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(xx[0] * xx[1] ** 2 * ufl.dx)))
    assert abs(moment - 1.0 / 6.0) < 1e-12


def _energies(mesh, steps=30):
    from fempm.particles.seeding import create_particles

    p = create_particles(mesh, 4, where=lambda y: (y[0] < 0.45) & (y[1] < 0.45) & (y[0] > 0.05) & (y[1] > 0.05),
                         seed=1)
    p.fields["start"] = p.x.copy()  # carried along: which particle is which on any partition
    p.fields["v"] = np.column_stack([0.5 * np.sin(4 * np.pi * p.x[:, 1]), 0.2 * np.cos(3 * np.pi * p.x[:, 0])])
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    bcs = [slip(V, lambda y: np.isclose(y[0], 0.0) | np.isclose(y[0], 1.0), (1.0, 0.0)),
           slip(V, lambda y: np.isclose(y[1], 0.0) | np.isclose(y[1], 1.0), (0.0, 1.0))]
    s = ExplicitSolver(V, p, [NeoHookean(1000.0, 0.3)], bcs=bcs, options=StepOptions(flip=0.95))
    for _ in range(steps):
        s.step(2e-4)
    e = s.energies()
    start = np.concatenate(comm.allgather(p.fields["start"]))
    xs = np.concatenate(comm.allgather(p.x))
    return e, xs[np.lexsort(start.T)]


def test_a_run_on_the_balanced_mesh_is_the_run_on_the_mesh():
    """Particles seeded in the cells (the same on any partition), 30 steps with particles
    crossing cells and ranks: positions and energies as on DOLFINx's own partition."""
    mesh = dolfinx.mesh.create_unit_square(comm, 24, 24, dolfinx.mesh.CellType.triangle)
    centres = dolfinx.mesh.compute_midpoints(mesh, 2, np.arange(mesh.topology.index_map(2).size_local, dtype=np.int32))
    blob = centres[(centres[:, 0] < 0.45) & (centres[:, 1] < 0.45)][:, :2]
    balanced = particle_balanced(mesh, blob)
    e0, x0 = _energies(mesh)
    e1, x1 = _energies(balanced)
    np.testing.assert_allclose(x1, x0, rtol=0, atol=1e-10)
    for k in ("kinetic", "strain"):
        assert abs(e1[k] - e0[k]) <= 1e-10 * abs(e0[k])


@pytest.mark.parametrize("cell_type", [dolfinx.mesh.CellType.triangle, dolfinx.mesh.CellType.quadrilateral])
def test_ghosts_hold_every_cell_around_a_rank_s_vertices(cell_type):
    """With ``ghosts=True`` every vertex of a rank's own cells has all its cells on that rank
    (owned or ghost): the count of local cells around it equals the count over all ranks."""
    mesh = dolfinx.mesh.create_unit_square(comm, 20, 16, cell_type)
    balanced = particle_balanced(mesh, _blob(3000), ghosts=True)
    top = balanced.topology
    top.create_connectivity(2, 0)
    c2v = top.connectivity(2, 0)
    vmap, owned = top.index_map(0), top.index_map(2).size_local
    cells = c2v.array.reshape(-1, len(c2v.links(0)))
    global_vertices = vmap.local_to_global(np.arange(vmap.size_local + vmap.num_ghosts, dtype=np.int32))
    n = vmap.size_global
    around_owned = np.bincount(global_vertices[cells[:owned].ravel()], minlength=n)
    around_local = np.bincount(global_vertices[cells.ravel()], minlength=n)
    total = comm.allreduce(around_owned)  # each cell counted once, on its owner
    mine = np.unique(global_vertices[cells[:owned].ravel()])
    assert np.array_equal(around_local[mine], total[mine])
    if comm.size > 1:
        assert top.index_map(2).num_ghosts > 0
