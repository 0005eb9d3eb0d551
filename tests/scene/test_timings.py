"""Where a run's time went: ``timings`` in the summary (each phase the slowest rank's) and in
the end-of-run line; the mesh cache from the command line."""

import json
import time
from pathlib import Path

import pytest
from mpi4py import MPI

from fempm.cli import main
from fempm.meshes.cache import set_mesh_cache
from fempm.scene import run
from fempm.scenes import vibrating_bar
from fempm.timings import PHASES, SETUP, Timings

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD


def _shared(tmp_path: Path) -> Path:
    return Path(comm.bcast(str(tmp_path) if comm.rank == 0 else None))


def test_a_phase_entered_inside_itself_counts_once():
    t = Timings()
    with t.phase("particles_s"):
        with t.phase("particles_s"):
            time.sleep(0.02)
        time.sleep(0.02)
    assert 0.04 <= t.seconds["particles_s"] < 0.2
    with pytest.raises(ValueError, match="unknown phase 'mesh'"), t.phase("mesh"):
        pass
    value = t.seconds["particles_s"]
    assert t.take() == {"particles_s": value}
    assert t.take() == {}


def test_the_summary_says_where_the_time_went(tmp_path, capsys):
    SETUP.take()
    scene = vibrating_bar(cells=8, t_end=4.0)
    assert scene.timings["mesh_s"] > 0 and scene.timings["particles_s"] > 0
    summary = run(scene, _shared(tmp_path) / "bar", checkpoint_every=50)
    timings = summary["timings"]
    assert list(timings) == list(PHASES)
    for name in PHASES:
        assert timings[name] > 0, name
    loop = sum(timings[k] for k in ("solver_s", "first_step_s", "steps_s", "output_s", "checkpoint_s"))
    assert loop <= summary["wall_time_s"] * 1.05 + 0.05
    written = json.loads((_shared(tmp_path) / "bar" / "summary.json").read_text())
    assert written["timings"] == pytest.approx(timings)
    # the slowest rank's
    assert comm.allreduce(timings["steps_s"], op=MPI.MIN) == timings["steps_s"]
    if comm.rank == 0:
        line = capsys.readouterr().out
        assert "mesh " in line and "first step " in line and "checkpoint " in line


def test_a_resumed_run_counts_reading_its_checkpoint(tmp_path):
    out = _shared(tmp_path) / "bar"
    run(vibrating_bar(cells=8, t_end=0.5), out, checkpoint_every=20, progress=False)
    summary = run(vibrating_bar(cells=8, t_end=1.0), out, resume=True, progress=False)
    assert summary["timings"]["checkpoint_s"] > 0 and summary["timings"]["first_step_s"] > 0


@pytest.fixture
def cache_back():
    yield
    set_mesh_cache()


def test_the_command_line_keeps_gmsh_meshes_where_it_is_told(tmp_path, cache_back):
    root = _shared(tmp_path)
    args = ["run", "silo", "--cells", "2", "--t-end", "2e-4", "--frames", "0", "--overwrite"]
    assert main([*args, "--out", str(root / "a"), "--mesh-cache", str(root / "meshes")]) == 0
    assert [p.name.split("-")[0] for p in (root / "meshes").iterdir()] == ["polygon"]
    first = json.loads((root / "a" / "summary.json").read_text())["timings"]["mesh_s"]
    assert main([*args, "--out", str(root / "b"), "--mesh-cache", str(root / "meshes")]) == 0
    second = json.loads((root / "b" / "summary.json").read_text())["timings"]["mesh_s"]
    assert second < first  # read, not meshed (the factor is measured at scale: docs/performance.md)
    assert main([*args, "--out", str(root / "c"), "--no-mesh-cache", "--refine", "1"]) == 0
    assert len(list((root / "meshes").iterdir())) == 1
    with pytest.raises(SystemExit):
        main([*args, "--out", str(root / "d"), "--no-mesh-cache", "--mesh-cache", str(root)])
