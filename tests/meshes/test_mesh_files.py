"""A .msh file that is not a readable gmsh mesh is one clear error on every rank (rank 0 reads
the file; before, its gmsh error left the other ranks waiting in the distribution)."""

from pathlib import Path

import pytest
from mpi4py import MPI

from fempm.meshes import MESHES, MeshFileError, read_msh

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD


@pytest.mark.parametrize("content", [b"", b"$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 2", None])
def test_an_unreadable_mesh_file_is_an_error_on_every_rank(tmp_path, content):
    path = Path(comm.bcast(str(tmp_path / "bad.msh") if comm.rank == 0 else None))
    if comm.rank == 0 and content is not None:
        path.write_bytes(content)
    comm.Barrier()
    with pytest.raises(MeshFileError, match="bad.msh' (is not a readable gmsh mesh|does not exist)"):
        read_msh(path, comm)


def test_the_shipped_mesh_reads_on_every_rank():
    mesh = read_msh(MESHES / "unit_square_tri.msh", comm, gdim=2).mesh
    assert comm.allreduce(mesh.topology.index_map(2).size_local) == 946


def test_a_mesh_without_physical_groups_is_named(tmp_path):
    """gmsh meshes every entity, DOLFINx reads the cells of physical groups only: the file is
    named and the fix said (DOLFINx said "No 'physical groups' in gmsh mesh. Cannot continue.")."""
    path = Path(comm.bcast(str(tmp_path / "plain.msh") if comm.rank == 0 else None))
    if comm.rank == 0:
        import gmsh

        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.occ.addRectangle(0.0, 0.0, 0.0, 1.0, 1.0)
        gmsh.model.occ.synchronize()
        gmsh.model.mesh.generate(2)
        gmsh.write(str(path))
        gmsh.finalize()
    comm.Barrier()
    with pytest.raises(MeshFileError, match="plain.msh' has no physical group of its 2-dimensional cells"):
        read_msh(path, comm)
