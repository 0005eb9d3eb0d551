"""VTKHDF particle frames: one file for all ranks, the ranks' rows in rank order, read back
exactly (h5py and pyvista); a rank that cannot write fails every rank, and no half-written
frame is left under the frame's name."""

from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from fempm.io import OutputWriteError, PointFileSeries, vtkhdf

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD


def _folder(tmp_path) -> Path:
    return Path(comm.bcast(str(tmp_path) if comm.rank == 0 else None))


def _rows(rank: int) -> int:
    return (0, 7, 3)[rank % 3] if comm.size > 1 else 5  # a rank without particles on 2 ranks


def _arrays(rank: int, d: int = 3, n: int | None = None):
    n = _rows(rank) if n is None else n
    rng = np.random.default_rng(rank)
    x = rng.random((n, d))
    return x, {"velocity": rng.random((n, d)), "stress": rng.random((n, d, d)), "J": rng.random(n),
               "X0": rng.random((n, d)), "id": np.arange(n, dtype=np.int64) + 100 * rank,
               "body": np.full(n, rank, dtype=np.int32)}


def _vtk(a: np.ndarray, vector: bool) -> np.ndarray:
    """VTK's layout, padded with zeros: vectors to 3 components, tensors to 3 x 3 (9)."""
    if a.ndim == 3:
        out = np.zeros((len(a), 3, 3))
        out[:, :a.shape[1], :a.shape[1]] = a
        return out.reshape(len(a), 9)
    if vector:
        return np.pad(a, ((0, 0), (0, 3 - a.shape[1])))
    return a


@pytest.mark.parametrize("d, n", [(3, None), (2, None), (2, vtkhdf.BLOCK + 5)])
def test_every_ranks_rows_in_one_file_in_rank_order(tmp_path, d, n):
    """Rank after rank, padded to VTK's 3 components and 3 x 3 tensors (a block at a time: more
    rows than a block too)."""
    path = _folder(tmp_path) / "frame.vtkhdf"
    x, data = _arrays(comm.rank, d, n)
    vtkhdf.write_points(path, comm, x, data, vectors=("velocity",))
    parts = [_arrays(r, d, n) for r in range(comm.size)]
    points, read = vtkhdf.read_points(path)
    np.testing.assert_array_equal(points, np.concatenate([_vtk(p[0], True) for p in parts]))
    for name in data:
        expected = np.concatenate([_vtk(p[1][name], name == "velocity") for p in parts])
        np.testing.assert_array_equal(read[name], expected)
        assert read[name].dtype == data[name].dtype
    assert read["stress"].shape[1] == 9 and read["velocity"].shape[1] == 3 and read["X0"].shape[1] == d
    if comm.rank == 0:
        pv = pytest.importorskip("pyvista")
        grid = pv.read(path)
        assert isinstance(grid, pv.UnstructuredGrid) and grid.n_points == grid.n_cells == len(points)
        np.testing.assert_array_equal(np.asarray(grid.points), points)
        np.testing.assert_array_equal(grid.point_data["stress"], read["stress"])
        assert sorted(q.name for q in path.parent.iterdir()) == ["frame.vtkhdf"]  # no temporary left


def test_a_rank_that_cannot_write_fails_every_rank(tmp_path, monkeypatch):
    folder = _folder(tmp_path)
    last = comm.size - 1

    def fail(*args):
        raise OSError("disk full")

    if comm.rank == last:
        monkeypatch.setattr(vtkhdf, "_fill", fail)
    series = PointFileSeries(folder, "particles", "particles", comm)
    x, data = _arrays(last if comm.size == 1 else comm.rank)
    if comm.rank == last and not len(x):  # the failing rank must have rows to write
        x, data = _arrays(1)
    with pytest.raises(OutputWriteError, match=f"writing particles frame 0 failed \\(rank {last}: disk full\\)"):
        series.write(0, 0.0, x, data)
    if comm.rank == 0:
        assert not (folder / "particles" / "particles_00000.vtkhdf").exists()
        assert not (folder / "particles.pvd").exists()
