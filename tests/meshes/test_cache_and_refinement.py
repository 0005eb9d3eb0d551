"""The mesh cache (a gmsh mesh made once, read on every rank after) and uniform refinement on
every rank (a large mesh from a coarse gmsh one), with the tags passed on."""

import json
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.mesh
from fempm.meshes import tagged_polygon, unstructured_box, unstructured_rectangle
from fempm.meshes.cache import CACHE_ENV, mesh_cache, set_mesh_cache
from fempm.meshes.refinement import refined

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD
SQUARE = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]


@pytest.fixture
def folder(tmp_path):
    """A fresh cache folder (rank 0's path on every rank), the cache set back afterwards."""
    path = Path(comm.bcast(str(tmp_path / "cache") if comm.rank == 0 else None))
    set_mesh_cache(path)
    yield path
    set_mesh_cache()


def _cells(mesh) -> int:
    return comm.allreduce(mesh.topology.index_map(mesh.topology.dim).size_local)


def _tagged_length(data, tag: int) -> float:
    """The total length of the facets tagged ``tag`` (2D)."""
    mesh = data.mesh
    facets = data.facet_tags.find(tag)
    mesh.topology.create_connectivity(1, 0)
    nodes = dolfinx.mesh.entities_to_geometry(mesh, 1, facets)
    x = mesh.geometry.x
    return comm.allreduce(float(np.linalg.norm(x[nodes[:, 1]] - x[nodes[:, 0]], axis=1).sum()))


def _area(mesh) -> float:
    import dolfinx.fem
    import ufl

    return comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(1.0 * ufl.dx(domain=mesh))))


def test_a_generated_mesh_is_written_once_and_read_back_the_same(folder):
    first = tagged_polygon(comm, SQUARE, 0.1, [1, 0, 2, 0])
    entries = sorted(folder.iterdir())
    assert len(entries) == 1 and entries[0].name.startswith("polygon-")
    meta = json.loads((entries[0] / "physical_groups.json").read_text())
    assert meta["generator"] == "polygon" and meta["params"]["tags"] == [1, 0, 2, 0]
    again = tagged_polygon(comm, SQUARE, 0.1, [1, 0, 2, 0])
    assert sorted(folder.iterdir()) == entries  # read, not made again
    for data in (first, again):  # the first run computes on the cached mesh too: the same cells
        assert _cells(data.mesh) == _cells(first.mesh)
        assert _tagged_length(data, 1) == pytest.approx(1.0, rel=1e-12)
        assert _tagged_length(data, 2) == pytest.approx(1.0, rel=1e-12)
    x0, x1 = (np.sort(np.concatenate(comm.allgather(d.mesh.geometry.x[:, 0]))) for d in (first, again))
    np.testing.assert_array_equal(x0, x1)


def test_other_parameters_are_other_entries(folder):
    unstructured_rectangle(comm, 0.25)
    unstructured_rectangle(comm, 0.25, seed=1)
    unstructured_rectangle(comm, 0.2)
    unstructured_box(comm, 0.5)
    names = sorted(p.name.split("-")[0] for p in folder.iterdir())
    assert names == ["box", "rectangle", "rectangle", "rectangle"]


def test_without_a_cache_nothing_is_written(folder, monkeypatch):
    set_mesh_cache(None)
    assert mesh_cache() is None
    unstructured_rectangle(comm, 0.25)
    assert not folder.exists()
    set_mesh_cache()
    monkeypatch.setenv(CACHE_ENV, "off")
    assert mesh_cache() is None
    monkeypatch.setenv(CACHE_ENV, str(folder))
    assert mesh_cache() == folder


def test_a_half_written_entry_is_not_read(folder):
    """An entry is renamed into place when complete: a temporary folder of a run that died is
    ignored (the mesh is made again)."""
    unstructured_rectangle(comm, 0.25)
    (entry,) = folder.iterdir()
    comm.barrier()
    if comm.rank == 0:
        entry.rename(entry.with_name(entry.name + ".tmp-dead"))
    comm.barrier()
    assert _cells(unstructured_rectangle(comm, 0.25)) > 0
    assert len([p for p in folder.iterdir() if ".tmp-" not in p.name]) == 1


@pytest.mark.parametrize("times", [1, 2])
def test_uniform_refinement_splits_every_triangle_into_four_and_keeps_the_tags(folder, times):
    coarse = tagged_polygon(comm, SQUARE, 0.2, [1, 0, 2, 0])
    fine = tagged_polygon(comm, SQUARE, 0.2 / 2**times, [1, 0, 2, 0], refine=times)
    assert _cells(fine.mesh) == 4**times * _cells(coarse.mesh)
    assert comm.allreduce(len(fine.facet_tags.find(1))) == 2**times * comm.allreduce(len(coarse.facet_tags.find(1)))
    for tag in (1, 2):
        assert _tagged_length(fine, tag) == pytest.approx(1.0, rel=1e-12)
    assert _area(fine.mesh) == pytest.approx(1.0, rel=1e-12)
    assert fine.mesh.topology.index_map(2).num_ghosts == 0  # as gmsh's reader makes them


def test_uniform_refinement_of_tetrahedra(folder):
    coarse = unstructured_box(comm, 0.5)
    fine = unstructured_box(comm, 0.25, refine=1)
    assert _cells(fine) == 8 * _cells(coarse)
    import dolfinx.fem
    import ufl

    assert comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(1.0 * ufl.dx(domain=fine)))) == pytest.approx(1.0)


def test_refinement_errors_name_the_problem(folder):
    with pytest.raises(ValueError, match="refine=1: uniform refinement splits triangles and tetrahedra only"):
        unstructured_rectangle(comm, 0.25, quadrilateral=True, refine=1)
    with pytest.raises(ValueError, match=r"refine=-1 must be a whole number of uniform refinements in \[0, 8\]"):
        unstructured_rectangle(comm, 0.25, refine=-1)
    with pytest.raises(ValueError, match="refine=1.5"):
        tagged_polygon(comm, SQUARE, 0.25, refine=1.5)
    quads = dolfinx.mesh.create_unit_square(comm, 2, 2, dolfinx.mesh.CellType.quadrilateral)
    from dolfinx.io.gmsh import MeshData

    with pytest.raises(ValueError, match="not quadrilateral cells"):
        refined(MeshData(quads, None, None, None, None, {}), 1)
