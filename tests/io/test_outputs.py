"""A run's outputs read back with pyvista: particle frames (VTKHDF, one file per frame for
all ranks, or parallel VTK XML pieces and their index; the time collection) and the grid fields (VTK XML time series); the energies and the
summary, also after a failed run; an earlier run's outputs refused or replaced."""

import csv
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from fempm.io import OutputFolderError
from fempm.scene import run
from fempm.scenes import two_disks
from fempm.stepping import SimulationError

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD
pv = pytest.importorskip("pyvista")


def _folder(tmp_path, name: str) -> Path:
    return Path(comm.bcast(str(tmp_path / name) if comm.rank == 0 else None))


def _gathered(particles) -> dict:
    ids = np.concatenate(comm.allgather(particles.ids))
    order = np.argsort(ids)
    return {"id": ids[order], "x": np.concatenate(comm.allgather(particles.x))[order],
            "v": np.concatenate(comm.allgather(particles.fields["v"]))[order],
            "J": np.concatenate(comm.allgather(np.linalg.det(particles.fields["F"])))[order]}


@pytest.mark.parametrize("frame_format, suffix", [("vtkhdf", ".vtkhdf"), ("vtu", ".pvtu")])
def test_particle_frames_are_files_that_pyvista_reads(tmp_path, frame_format, suffix):
    out = _folder(tmp_path, "disks")
    result = run(two_disks(cells=10, t_end=0.3, frames=3), out, progress=False, frame_format=frame_format)
    final = _gathered(result["solver"].particles)
    with pytest.raises(ValueError, match="unknown frame_format='xdmf'; expected one of vtkhdf, vtu"):
        run(two_disks(cells=10, t_end=0.3, frames=3), out, progress=False, frame_format="xdmf")
    if comm.rank != 0:
        return
    frames = sorted((out / "particles").glob(f"particles_*{suffix}"))
    times = [float(t) for _, t in csv.reader(open(out / "particles" / "times.csv"))]
    assert len(frames) == len(times) == 4 and times[0] == 0.0 and times[-1] == 0.3  # 3 frames + the final state
    pieces = sorted((out / "particles").glob(frames[-1].stem + "_r*.vtu"))
    assert len(pieces) == (comm.size if frame_format == "vtu" else 0)  # one per rank, or one file for all
    assert sorted(q.suffix for q in (out / "particles").iterdir()) == sorted(
        [".csv"] + [suffix] * 4 + [".vtu"] * len(pieces) * 4)  # nothing else left (no temporary file)
    grid = pv.read(frames[-1])
    assert isinstance(grid, pv.UnstructuredGrid) and grid.n_cells == grid.n_points  # a vertex per particle
    assert grid.n_points == len(final["id"]) == result["particles"]
    order = np.argsort(grid.point_data["id"])
    assert np.array_equal(grid.point_data["id"][order], final["id"])
    assert np.array_equal(np.asarray(grid.points)[order, :2], final["x"])  # float64, exact
    assert np.array_equal(grid.point_data["velocity"][order, :2], final["v"])
    assert np.allclose(grid.point_data["J"][order], final["J"], rtol=0, atol=1e-15)
    assert grid.point_data["stress"].shape == (grid.n_points, 9)
    reader = pv.PVDReader(out / "particles.pvd")  # the time series
    assert np.allclose(reader.time_values, times)
    reader.set_active_time_value(times[1])
    assert reader.read()[0].n_points == result["particles"]
    rows = list(csv.DictReader(open(out / "energies.csv")))
    assert len(rows) == result["steps"] and float(rows[-1]["t"]) == 0.3
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["steps"] == result["steps"]


def test_grid_frames_include_the_final_state_and_pyvista_reads_them(tmp_path):
    """grid_velocity.pvd and grid_stress.pvd: a frame per particle frame (at t = 0 the
    velocity mapped from the particles) and the final state, which is the solver's last grid
    velocity at the dofs."""
    out = _folder(tmp_path, "disks")
    result = run(two_disks(cells=10, t_end=0.3, frames=3), out, progress=False)
    solver = result["solver"]
    V = solver.V
    imap = V.dofmap.index_map
    owned = imap.size_local
    gdofs = imap.local_to_global(np.arange(owned, dtype=np.int32))
    x = V.tabulate_dof_coordinates()[:owned, :2]
    v = solver.grid_velocity[:owned]
    xs, vs = np.concatenate(comm.allgather(x)), np.concatenate(comm.allgather(v))
    assert len(np.unique(np.concatenate(comm.allgather(gdofs)))) == len(xs)
    if comm.rank != 0:
        return
    # the pieces lie in grid/ (one per rank and frame) as the particles' in particles/, not beside the collections
    assert sorted(q.name for q in out.iterdir() if q.is_file()) == [
        "energies.csv", "grid_stress.pvd", "grid_velocity.pvd", "particles.pvd", "summary.json"]
    assert len(list((out / "grid").glob("grid_velocity_*_r*.vtu"))) == 4 * comm.size
    assert len(list((out / "grid").glob("grid_stress_*.pvtu"))) == 4
    for name in ("grid_velocity", "grid_stress"):
        reader = pv.PVDReader(out / f"{name}.pvd")
        # at every particle frame (t = 0: the mapped velocity) and at the end
        assert reader.time_values[0] == 0.0 and reader.time_values[-1] == 0.3 and len(reader.time_values) == 4
    reader = pv.PVDReader(out / "grid_velocity.pvd")
    reader.set_active_time_value(0.0)  # mapped from the disks' initial velocities +-(0.1, 0.1)
    first = reader.read().combine(merge_points=True).point_data["grid_velocity"][:, :2]
    assert np.abs(np.abs(first).max(axis=0) - 0.1).max() < 1e-12
    reader.set_active_time_value(reader.time_values[-1])
    grid = reader.read().combine(merge_points=True)
    pts, vel = np.asarray(grid.points)[:, :2], grid.point_data["grid_velocity"][:, :2]
    for k in np.flatnonzero(np.linalg.norm(vs, axis=1) > 0)[:50]:  # the written field at the dofs
        near = np.argmin(np.linalg.norm(pts - xs[k], axis=1))
        assert np.linalg.norm(pts[near] - xs[k]) < 1e-12 and np.allclose(vel[near], vs[k], rtol=0, atol=1e-14)


def test_a_failed_run_leaves_its_summary_and_failing_state(tmp_path):
    out = _folder(tmp_path, "fail")
    def invert(solver):  # after step 3, J < 0 for the first particle of each rank
        if solver.step_count == 3:
            solver.particles.fields["F"][:1, 0, :] *= -1.0

    with pytest.raises(SimulationError, match="inverted deformation"):
        run(two_disks(cells=10, t_end=0.3, frames=3), out, progress=False, callback=invert)
    if comm.rank == 0:
        summary = json.loads((out / "summary.json").read_text())
        assert summary["status"] == "aborted" and "inverted deformation" in summary["health"]["error"]
        frames = sorted((out / "particles").glob("particles_*.vtkhdf"))
        assert pv.read(frames[-1]).n_points == summary["particles"]


def test_an_earlier_run_is_refused_or_replaced(tmp_path):
    out = _folder(tmp_path, "again")
    run(two_disks(cells=10, t_end=0.2, frames=4), out, progress=False)
    with pytest.raises(OutputFolderError, match="holds the outputs of an earlier run .* give --overwrite"):
        run(two_disks(cells=10, t_end=0.1, frames=1), out, progress=False, overwrite=False)
    run(two_disks(cells=10, t_end=0.1, frames=1), out, progress=False)  # overwrite=True: replaced
    if comm.rank == 0:  # no frame of the earlier run is left
        assert len(list((out / "particles").glob("particles_*.vtkhdf"))) == 2
        assert len(list(csv.reader(open(out / "particles" / "times.csv")))) == 2


def test_a_run_computes_only_the_outputs_its_scene_asks_for(tmp_path, monkeypatch):
    from fempm.stepping import ExplicitSolver

    projections = []
    original = ExplicitSolver.grid_stress
    monkeypatch.setattr(ExplicitSolver, "grid_stress", lambda self, *a, **k: projections.append(1) or original(self))
    out = _folder(tmp_path, "velocity-only")
    scene = dataclasses.replace(two_disks(cells=10, t_end=0.2, frames=4), outputs=("grid_velocity",))
    run(scene, out, progress=False)
    assert projections == []  # the grid stress is never projected
    if comm.rank == 0:
        assert (out / "grid_velocity.pvd").exists() and not (out / "grid_stress.pvd").exists()
        assert len(list((out / "particles").glob("*.vtkhdf"))) == 1  # the final state only
    with pytest.raises(ValueError, match=r"unknown output\(s\) \['stress'\]"):
        dataclasses.replace(scene, outputs=("stress",))
