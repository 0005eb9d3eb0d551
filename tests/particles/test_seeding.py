import fempm
import numpy as np
import pytest
from conftest import make_mesh
from mpi4py import MPI

from fempm.particles.seeding import reference_pattern

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)


@pytest.mark.parametrize("cell,ppc", [("interval", 3), ("triangle", 9), ("quadrilateral", 4), ("tetrahedron", 27), ("hexahedron", 8)])
def test_reference_pattern_equal_subcells(cell, ppc):
    subs = reference_pattern(cell, ppc)
    assert subs.shape[0] == ppc
    c = subs.mean(axis=1)
    assert len(np.unique(np.round(c, 12), axis=0)) == ppc  # distinct centroids
    if subs.shape[1] > 2:  # simplices: equal volumes summing to the reference volume
        d = subs.shape[2]
        vol = np.abs(np.linalg.det(subs[:, 1:] - subs[:, :1])) / np.prod(np.arange(1, d + 1))
        np.testing.assert_allclose(vol, vol[0], rtol=1e-12)
        np.testing.assert_allclose(vol.sum(), 1.0 / np.prod(np.arange(1, d + 1)), rtol=1e-12)
        assert np.all(c >= 0) and np.all(c.sum(axis=1) <= 1)


def test_ppc_not_a_power_is_rejected():
    with pytest.raises(ValueError, match="ppc=5"):
        reference_pattern("triangle", 5)


def test_seeding_volume_mass_and_location(mesh_name):
    mesh = make_mesh(mesh_name)
    p = fempm.create_particles(mesh, 2 ** mesh.topology.dim, density=3.0, jitter=0.7, seed=4)
    geom = p.locator.geometry
    vol = mesh.comm.allreduce(geom.cell_volumes()[: geom.num_owned].sum())
    assert mesh.comm.allreduce(p.volume.sum()) == pytest.approx(vol, rel=1e-12)
    assert mesh.comm.allreduce(p.mass.sum()) == pytest.approx(3.0 * vol, rel=1e-12)
    # the stored cell and reference coordinates are what location finds
    assert geom.contains(p.X).all()
    np.testing.assert_allclose(geom.push_forward(p.cells, p.X), p.x, atol=1e-12)
    cells, X = p.locator.locate(p.x)
    assert np.all(cells >= 0)
    np.testing.assert_allclose(geom.push_forward(cells, X), p.x, atol=1e-11)
    assert len(np.unique(p.ids)) == len(p)


def test_jitter_is_reproducible_and_bounded():
    mesh = make_mesh("triangle")
    a = fempm.create_particles(mesh, 4, jitter=1.0, seed=11)
    b = fempm.create_particles(mesh, 4, jitter=1.0, seed=11)
    c = fempm.create_particles(mesh, 4, jitter=1.0, seed=12)
    np.testing.assert_array_equal(a.x, b.x)
    assert np.abs(a.x - c.x).max() > 1e-3
    with pytest.raises(ValueError, match="jitter"):
        fempm.create_particles(mesh, 4, jitter=1.5)


def test_seeded_ids_do_not_depend_on_partition():
    """Particle ids and positions are a function of the original cell, not of the rank."""
    comm = MPI.COMM_WORLD
    world = fempm.create_particles(make_mesh("quadrilateral", comm), 4, jitter=0.5, seed=3)
    serial = fempm.create_particles(make_mesh("quadrilateral", MPI.COMM_SELF), 4, jitter=0.5, seed=3)
    order = np.argsort(serial.ids)
    pos = np.searchsorted(serial.ids[order], world.ids)
    np.testing.assert_array_equal(serial.ids[order][pos], world.ids)
    np.testing.assert_allclose(serial.x[order][pos], world.x, atol=1e-14)
