"""Run health (fempm.stepping.health): unstable runs stop with a SimulationError that names the cause and
a non-zero exit from the CLI, with their summary written; healthy runs record their figures."""

import json
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from fempm.cli import main
from fempm.stepping.health import Health, HealthMonitor
from fempm.scene import run
from fempm.scenes import hanging_block, two_disks, vibrating_bar
from fempm.stepping import SimulationError

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD


def _out(tmp_path):
    return comm.bcast(str(tmp_path), root=0)


@pytest.mark.parametrize("argv, cause", [
    (["disks", "--nu", "0.4999"], "energy growth"),  # was: energy x18, exit 0
    (["bar", "--cfl", "0.9", "--scheme", "USL"], "energy growth"),  # was: energy x506 before J <= 0
    (["disks", "--speed", "10"], "J = det F"),        # was: J ~ 3e-6, no abort
])
def test_unstable_cli_runs_exit_nonzero_naming_the_cause(tmp_path, capsys, argv, cause):
    out = Path(_out(tmp_path)) / "run"
    assert main(["run", *argv, "--out", str(out)]) == 3
    if comm.rank == 0:
        assert cause in capsys.readouterr().err
        summary = json.loads((out / "summary.json").read_text())
        assert summary["status"] == "aborted" and cause in summary["health"]["error"]
        assert len(list((out / "particles").glob("*.vtkhdf"))) >= 2  # the failing state is written


def test_default_scheme_runs_the_bar_at_cfl_0_9_within_5_percent(tmp_path):
    """MUSL, the default scheme since the stability catalogue, is stable where USL was not."""
    out = Path(_out(tmp_path)) / "bar"
    assert main(["run", "bar", "--cfl", "0.9", "--out", str(out)]) == 0
    if comm.rank == 0:
        summary = json.loads((out / "summary.json").read_text())
        assert summary["status"] == "completed" and abs(summary["health"]["energy_ratio"] - 1) < 0.05


def test_energy_check_stops_before_growth_exceeds_the_tolerance():
    scene = two_disks(cells=10, nu=0.4999, t_end=2.5, frames=0, comm=comm)
    with pytest.raises(SimulationError, match="energy growth") as e:
        run(scene, None, progress=False)
    assert 1.2 < e.value.health["energy_ratio"] < 2.0  # caught at the first step above 20 %, not at x18


def test_healthy_run_records_its_figures_and_the_work_of_gravity():
    scene = hanging_block(cells=4, t_end=0.05, comm=comm)
    s = run(scene, None, progress=False)
    h = s["health"]
    assert s["status"] == "completed" and h["outcome"] == "completed" and h["error"] is None
    assert h["external_work"] > 0  # gravity does work on the falling block
    assert 0.5 < h["energy_ratio"] <= 1.2 and 0.0 < h["j_min"] <= 1.0 <= h["j_max"] < 100.0
    assert np.isfinite(h["momentum_drift"])
    s = run(vibrating_bar(cells=8, t_end=2.0, comm=comm), None, progress=False)
    assert abs(s["health"]["energy_ratio"] - 1) < 0.05 and s["health"]["external_work"] == 0.0


def test_j_bounds_and_step_floor_are_options():
    scene = vibrating_bar(cells=8, v0=2.0, t_end=5.0, comm=comm)
    scene.health = Health(j_max=1.05)
    with pytest.raises(SimulationError, match=r"left the bounds \[0.01, 1.05\]"):
        run(scene, None, progress=False)
    solver = vibrating_bar(cells=8, comm=comm).solver()
    monitor = HealthMonitor(solver, Health(dt_floor=1e-3))
    dt = solver.step()
    monitor.after_step(dt, solver.energies())
    solver.step(dt=1e-6 * dt)
    with pytest.raises(SimulationError, match="time step collapse"):
        monitor.after_step(1e-6 * dt, solver.energies())


@pytest.mark.parametrize("kw", [dict(energy_tolerance=0.0), dict(j_min=1.5), dict(j_max=0.5), dict(dt_floor=1.0)])
def test_bad_limits_are_errors(kw):
    with pytest.raises(ValueError):
        Health(**kw)


def test_cli_health_options(tmp_path, capsys):
    out = Path(_out(tmp_path)) / "bar"
    assert main(["run", "bar", "--cells", "8", "--t-end", "2", "--energy-tolerance", "none", "--j-max", "50",
                 "--out", str(out)]) == 0
    if comm.rank == 0:
        limits = json.loads((out / "summary.json").read_text())["health"]["limits"]
        assert limits["energy_tolerance"] is None and limits["j_max"] == 50.0
    capsys.readouterr()
    assert main(["run", "bar", "--j-min", "abc"]) == 2  # a usage error, on every rank
    if comm.rank == 0:
        assert "fempm run: option --j-min expects a number, got 'abc'" in capsys.readouterr().err
