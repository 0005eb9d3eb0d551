"""Shared mesh factories for the tests (each takes a communicator)."""

from __future__ import annotations

from pathlib import Path

import fempm  # noqa: F401  (imports dolfinx_solver first)
import dolfinx.mesh as dm
import numpy as np
import pytest
from mpi4py import MPI

MESHES = Path(__file__).resolve().parents[1] / "meshes"


def _perturb(mesh: dm.Mesh, amp: float = 0.06) -> dm.Mesh:
    """Move interior nodes of a unit square/cube mesh smoothly: quads/hexes become non-affine."""
    x = mesh.geometry.x
    gdim = mesh.geometry.dim
    bump = np.prod(np.sin(np.pi * x[:, :gdim]), axis=1)
    for d in range(gdim):
        x[:, d] += amp * bump * np.sin(2 * np.pi * x[:, (d + 1) % gdim] + d)
    return mesh


def _read(name: str):
    def make(comm):
        from fempm.meshes import read_msh

        return read_msh(MESHES / name, comm).mesh

    return make


MESH_FACTORIES = {
    "interval": lambda comm: dm.create_unit_interval(comm, 9),
    "triangle": lambda comm: dm.create_unit_square(comm, 6, 5),
    "quadrilateral": lambda comm: dm.create_unit_square(comm, 6, 5, dm.CellType.quadrilateral),
    "tetrahedron": lambda comm: dm.create_unit_cube(comm, 3, 3, 2),
    "hexahedron": lambda comm: dm.create_unit_cube(comm, 3, 3, 2, dm.CellType.hexahedron),
    "distorted-quadrilateral": lambda comm: _perturb(dm.create_unit_square(comm, 6, 5, dm.CellType.quadrilateral)),
    "distorted-hexahedron": lambda comm: _perturb(dm.create_unit_cube(comm, 3, 3, 3, dm.CellType.hexahedron)),
    "unstructured-triangle": _read("plate_with_hole.msh"),
    "unstructured-quadrilateral": _read("square_quads.msh"),
    "unstructured-tetrahedron": _read("cube_tets.msh"),
}


@pytest.fixture(params=sorted(MESH_FACTORIES))
def mesh_name(request):
    return request.param


def make_mesh(name: str, comm=MPI.COMM_WORLD) -> dm.Mesh:
    return MESH_FACTORIES[name](comm)


def ppc_for(mesh: dm.Mesh, degree: int) -> int:
    """Particles per cell: at least the dofs per cell of a Lagrange space of this degree."""
    tdim = mesh.topology.dim
    n = degree + 1
    return n**tdim


def pytest_collection_modifyitems(config, items):
    """Under MPI, a test marked ``parallel(only=(id, ...))`` runs only the parametrizations of
    those ids: the 2-rank pass takes one or two of a matrix whose other entries test the same
    parallel code (every entry still runs serially)."""
    if MPI.COMM_WORLD.size == 1:
        return
    kept, dropped = [], []
    for item in items:
        mark = item.get_closest_marker("parallel")
        only = mark.kwargs.get("only") if mark is not None else None
        callspec = getattr(item, "callspec", None)
        (dropped if only is not None and callspec is not None and callspec.id not in only else kept).append(item)
    if dropped:
        config.hook.pytest_deselected(items=dropped)
        items[:] = kept


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Under MPI a test failing on one rank leaves the others waiting in a collective:
    print the failure and abort the whole run at once instead of hanging."""
    outcome = yield
    report = outcome.get_result()
    if report.failed and MPI.COMM_WORLD.size > 1:
        import sys

        sys.stderr.write(f"\n[rank {MPI.COMM_WORLD.rank}] FAILED {item.nodeid}\n{report.longreprtext}\n")
        sys.stderr.flush()
        MPI.COMM_WORLD.Abort(1)


def shared_tmp(tmp_path_factory, name: str) -> str:
    """A temporary folder made on rank 0 and known to every rank (for studies run under MPI)."""
    out = tmp_path_factory.mktemp(name) if MPI.COMM_WORLD.rank == 0 else None
    return MPI.COMM_WORLD.bcast(str(out), root=0)


def quick_study(tmp_path_factory, name: str, run) -> tuple[str, list[dict]]:
    """(the folder, the rows) of ``run(folder, quick=True)``, a study at its quick size, silent."""
    out = shared_tmp(tmp_path_factory, name)
    return out, run(out, quick=True, log=lambda *a: None)


@pytest.fixture
def petsc_options():
    """Options set in the PETSc database for one test, removed after it."""
    from petsc4py import PETSc

    opts = PETSc.Options()
    added = []

    def put(**values):
        for k, v in values.items():
            opts[k] = v
            added.append(k)

    yield put
    for k in added:
        opts.delValue(k)
