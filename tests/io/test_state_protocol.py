"""The checkpointed components share one protocol, state_dict() / load_state_dict(): the
solver (with its step record, removed particles and colliders), the run-health monitor and a
scene's watch each give back on a fresh instance the state they were given, and the checkpoint
module reaches them through that protocol only (no setattr, no private members)."""

import ast
import dataclasses
from pathlib import Path

import numpy as np
import pytest

import fempm  # noqa: F401  (before dolfinx)
from fempm.scenes.footing import footing
from fempm.stepping.health import HealthMonitor

CHECKPOINT = Path(fempm.__file__).parent / "io" / "checkpoint.py"


def _same(a, b):
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (np.ndarray, list, tuple)):
        return np.array_equal(np.asarray(a), np.asarray(b))
    return a == b


@pytest.mark.parallel
def test_solver_monitor_and_watch_give_back_their_state():
    scene = footing(cells=4)
    solver = scene.solver()
    monitor = HealthMonitor(solver, scene.health)
    for _ in range(12):
        dt = solver.step()
        monitor.after_step(dt, solver.energies())
        scene.watch(solver)
    assert solver.collisions.state_dict()["impulse"] != [[0.0, 0.0]]  # the footing pressed
    state, health, watch = solver.state_dict(), monitor.state_dict(), scene.watch.state_dict()
    assert state["step_count"] == 12 and state["arrays"]["grid_velocity"].shape[1] == 2

    fresh = footing(cells=4)
    again = fresh.solver()
    again.load_state_dict(state)
    assert _same(again.state_dict(), state)
    monitor2 = HealthMonitor(again, fresh.health)
    monitor2.load_state_dict(health)
    assert _same(monitor2.state_dict(), health)
    fresh.watch.load_state_dict(watch)
    assert _same(fresh.watch.state_dict(), watch)
    with pytest.raises(ValueError, match="lacks e0"):
        monitor2.load_state_dict({k: v for k, v in health.items() if k != "e0"})


def test_a_removed_account_and_a_step_record_round_trip():
    from fempm.stepping.outside import Outside, Removed
    from fempm.stepping.record import StepRecord

    out = Outside("remove")
    out.removed = Removed(count=3, mass=1.5, kinetic=0.25, strain=0.125, momentum=[1.0, -2.0])
    other = Outside("remove")
    other.load_state_dict(out.state_dict())
    assert dataclasses.asdict(other.removed) == dataclasses.asdict(out.removed)
    record = StepRecord(j_range=(0.5, 1.5), mass_ratio=0.7, extended_steps=2, newton_iterations=9, cut_steps=1)
    record.terms.update(internal=4)
    copy = StepRecord()
    copy.load_state_dict(record.state_dict())
    assert copy.state_dict() == record.state_dict() and copy.j_range == (0.5, 1.5)


def test_the_checkpoint_module_calls_the_protocol_only():
    tree = ast.parse(CHECKPOINT.read_text())
    calls = {n.func.id for n in ast.walk(tree) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)}
    assert "setattr" not in calls
    private = sorted({n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute)
                      and n.attr.startswith("_") and not n.attr.startswith("__")
                      and not (isinstance(n.value, ast.Name) and n.value.id == "self")})
    assert private == [], private
    used = {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute)}
    assert {"state_dict", "load_state_dict"} <= used
    assert not {"restore", "restore_state", "checkpoint_state"} & used
