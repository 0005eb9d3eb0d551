"""The scenes in 3D (``dim=3``, ``--dim 3``): the channel dam break and the compaction column
give their plane-strain answers, the spheres keep their momentum, the square column and the
square footing run to the end with sane results, from Python and from the command line on 1
and 2 ranks with their frames."""

import json
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from fempm.cli import main
from fempm.scene import run
from fempm.scenes import column_collapse, compaction, dam_break, footing, surge_front, two_disks

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD


def test_the_dam_in_a_channel_is_the_plane_dam():
    """Slip walls on both sides of the channel: every slice moves as the plane-strain water."""
    fronts = []
    for dim in (2, 3):
        scene = dam_break(cells=4, dim=dim, t_end=0.1)
        summary = run(scene, progress=False)
        assert summary["status"] == "completed"
        fronts.append(surge_front(scene.particles, scene.params))
    assert fronts[1] == pytest.approx(fronts[0], rel=1e-6) and fronts[0] > 1.2


def test_the_compaction_column_in_3d_is_the_plane_one():
    errors = [run(compaction(cells=8, dim=dim), progress=False)["stress_error"] for dim in (2, 3)]
    assert errors[1] == pytest.approx(errors[0], rel=1e-10) and errors[0] < 0.1


@pytest.mark.parametrize("mesh", ["structured", "unstructured"])
def test_two_spheres_keep_their_momentum(mesh):
    scene = two_disks(cells=8, dim=3, mesh=mesh, t_end=1.0)
    volume = comm.allreduce(float(scene.particles.volume.sum()))
    assert volume == pytest.approx(2 * 4 / 3 * np.pi * 0.2**3, rel=0.15)  # the seeded spheres
    summary = run(scene, progress=False)
    assert summary["status"] == "completed" and summary["health"]["momentum_drift"] < 1e-13


def test_the_square_column_spreads_less_than_the_plane_one():
    """Axisymmetric-like spreading: the same column's runout along x is smaller in 3D."""
    runouts = [run(column_collapse(cells=4, dim=dim, t_end=0.3), progress=False) for dim in (2, 3)]
    assert all(r["status"] == "completed" for r in runouts)
    assert 0.0 < runouts[1]["runout"] < runouts[0]["runout"] and runouts[1]["final_height"] < 1.0


def test_the_square_footing_bears_on_its_area():
    summary = run(footing(cells=2, dim=3, depth=0.1), progress=False)
    assert summary["status"] == "completed" and summary["bearing_pressure"] > 0
    assert summary["skempton"] == pytest.approx(6.2 * 1.0e4, rel=1e-12)
    assert summary["bearing_ratio"] == pytest.approx(summary["bearing_pressure"] / summary["skempton"])


@pytest.mark.parametrize("scene, options", [
    ("column", ["--cells", "2", "--t-end", "0.02"]),
    ("dam", ["--cells", "2", "--t-end", "0.02"]),
    ("compaction", ["--cells", "4"]),
    ("disks", ["--cells", "6", "--t-end", "0.05"]),
    ("footing", ["--cells", "2", "--depth", "0.02"]),
])
def test_3d_from_the_command_line_with_frames(tmp_path, scene, options):
    out = Path(comm.bcast(str(tmp_path / scene) if comm.rank == 0 else None))
    assert main(["run", scene, "--dim", "3", "--frames", "2", "--out", str(out), *options]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["params"]["dim"] == 3
    if comm.rank == 0:
        pv = pytest.importorskip("pyvista")
        frame = pv.read(sorted((out / "particles").glob("particles_*.vtkhdf"))[-1])
        assert frame.n_points == summary["particles"] and np.ptp(np.asarray(frame.points)[:, 2]) > 0


def test_a_dimension_other_than_2_or_3_is_named():
    with pytest.raises(ValueError, match=r"dim=4 must be 2 \(plane strain\) or 3"):
        column_collapse(dim=4)
