"""Checkpoint and restart (fempm.io.checkpoint): a run interrupted at t = 1 and resumed to t = 2
writes bit for bit what the uninterrupted run writes, on 1 and on 2 ranks; a checkpoint of
one number of ranks resumes on another to round-off."""

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from fempm.io.checkpoint import CheckpointError, RunInterrupted, manifest
from fempm.scene import run
from fempm.scenes import two_disks

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD
T_STOP, T_END = 1.0, 2.0


def _folder(tmp_path, name: str) -> Path:
    """One folder for all ranks (rank 0's pytest temporary folder)."""
    return Path(comm.bcast(str(tmp_path / name) if comm.rank == 0 else None))


def _disks(c=comm, t_end=T_END, mass="lumped"):
    """The two disks; ``mass`` "consistent+contact": a consistent matrix per disk (contact),
    "consistent+cpdi1": consistent mass of CPDI1 domains."""
    mass, _, more = mass.partition("+")
    scene = two_disks(cells=10, ppc=4, t_end=t_end, frames=8, comm=c, mass=mass, contact=more == "contact")
    if more == "cpdi1":
        scene = dataclasses.replace(scene, options=dataclasses.replace(scene.options, domain="cpdi1"))
    return scene


def _interrupt_at(t_stop: float):
    """A callback that sends SIGINT to this process at the first step past ``t_stop`` (every
    rank reaches it at the same step)."""
    def callback(solver):
        if solver.t >= t_stop and not callback.sent:
            callback.sent = True
            os.kill(os.getpid(), signal.SIGINT)
    callback.sent = False
    return callback


def _interrupted_then_resumed(out: Path, c=comm, mass="lumped") -> dict:
    with pytest.raises(RunInterrupted, match="interrupted by SIGINT") as e:
        run(_disks(c, mass=mass), out, progress=False, checkpoint_every=1000, callback=_interrupt_at(T_STOP))
    assert e.value.signum == signal.SIGINT
    data = manifest(out)
    assert T_STOP <= data["t"] < T_END and data["ranks"] == c.size
    if c.rank == 0:
        assert json.loads((out / "summary.json").read_text())["status"] == "interrupted"
    return data


#: the summary entries that measure the machine, not the run
TIMINGS = ("wall_time_s", "particle_steps_per_s", "timings")


def outputs(out: Path) -> dict[str, bytes]:
    """Every file a run wrote into ``out`` but its checkpoints, by relative path (the summary
    without its timings)."""
    files = {str(q.relative_to(out)): q.read_bytes() for q in sorted(out.rglob("*"))
             if q.is_file() and not q.relative_to(out).parts[0].startswith("checkpoint")}
    summary = json.loads(files.pop("summary.json"))
    files["summary.json"] = json.dumps({k: v for k, v in summary.items() if k not in TIMINGS}, sort_keys=True).encode()
    return files


def assert_same_outputs(parts: Path, whole: Path) -> None:
    """The interrupted-and-resumed run wrote byte for byte what the uninterrupted one wrote."""
    a, b = outputs(parts), outputs(whole)
    assert sorted(a) == sorted(b)
    assert [k for k in a if a[k] != b[k]] == []


@pytest.mark.parametrize("mass", ["lumped", "consistent", *(pytest.param(m, marks=pytest.mark.slow)
                                                           for m in ("consistent+contact", "consistent+cpdi1"))])
def test_resumed_run_is_bit_identical_to_the_uninterrupted_one(tmp_path, mass):
    """Every output: energies.csv, the particle frames and the grid series (pieces, indexes,
    collections, times) and the summary's totals. Consistent mass: the checkpoint holds the
    kept systems (sparsity, the values each preconditioner was set up from, the warm starts;
    with contact each body's, with particle domains those over the cells' vertex stars), so
    the resumed solves repeat the uninterrupted ones."""
    whole, parts = _folder(tmp_path, "whole"), _folder(tmp_path, "parts")
    reference = run(_disks(mass=mass), whole, progress=False)
    stop = _interrupted_then_resumed(parts, mass=mass)
    resumed = run(_disks(mass=mass), parts, progress=False, resume=True)
    assert resumed["status"] == "completed" and resumed["steps"] == reference["steps"] > stop["step_count"] > 20
    assert len(resumed["history"]) - 1 == reference["steps"] - stop["step_count"]  # continued, not run again
    assert resumed["t_end"] == reference["t_end"] == T_END
    if comm.rank == 0:
        assert b"\r" not in (parts / "energies.csv").read_bytes()
        assert len(list((whole / "grid").glob("grid_velocity_*.pvtu"))) == 9  # 8 frames from t = 0, and t_end
        assert_same_outputs(parts, whole)
        assert resumed["final"] == reference["final"]


def _positions(particles) -> np.ndarray:
    ids = np.concatenate(particles.comm.allgather(particles.ids))
    x = np.concatenate(particles.comm.allgather(particles.x))
    v = np.concatenate(particles.comm.allgather(particles.fields["v"]))
    order = np.argsort(ids)
    return np.hstack([x[order], v[order]])


@pytest.mark.skipif(comm.size != 2, reason="moves a checkpoint between 1 and 2 ranks")
def test_checkpoints_resume_on_another_number_of_ranks(tmp_path):
    """2 ranks -> 1 rank and 1 rank -> 2 ranks: final positions and velocities agree with the
    uninterrupted 2-rank run to 1e-12."""
    whole = _folder(tmp_path, "whole")
    reference = _positions(run(_disks(), whole, progress=False)["solver"].particles)
    two = _folder(tmp_path, "from-two")
    _interrupted_then_resumed(two)
    one = _folder(tmp_path, "from-one")
    if comm.rank == 0:
        solver = run(_disks(MPI.COMM_SELF), two, progress=False, resume=True)["solver"]
        assert np.abs(_positions(solver.particles) - reference).max() < 1e-12
        _interrupted_then_resumed(one, MPI.COMM_SELF)
    comm.Barrier()
    resumed = run(_disks(), one, progress=False, resume=True)
    assert np.abs(_positions(resumed["solver"].particles) - reference).max() < 1e-12


@pytest.mark.skipif(comm.size > 1, reason="starts its own processes")
def test_command_line_checkpoint_resume_and_sigterm(tmp_path):
    """`run --checkpoint-every`, `resume --t-end` beyond the end, SIGTERM stopping a run with
    a checkpoint and exit code 143, and `resume` of a folder without a checkpoint."""
    cmd = [sys.executable, "-m", "fempm"]
    out = tmp_path / "disks"
    r = subprocess.run(cmd + ["run", "disks", "--cells", "10", "--t-end", "0.5", "--checkpoint-every", "4", "--out",
                              str(out)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    first = manifest(out)
    assert first["t"] == 0.5 and first["rebuild"]["options"] == {"cells": 10, "t_end": 0.5}
    r = subprocess.run(cmd + ["resume", str(out), "--t-end", "1.0"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["t_end"] == 1.0 and summary["steps"] > first["step_count"]
    rows = (out / "energies.csv").read_text().splitlines()
    assert len(rows) == 1 + summary["steps"] and [int(r.split(",")[0]) for r in rows[1:]] == \
        list(range(1, summary["steps"] + 1))
    r = subprocess.run(cmd + ["resume", str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "no checkpoint in" in r.stderr and "Traceback" not in r.stderr
    # SIGTERM: the run stops at a step boundary with a checkpoint, exit code 128 + 15
    slow = tmp_path / "slow"
    # a run that cannot end before the signal (the disks reach the walls within a second of wall time)
    proc = subprocess.Popen(cmd + ["run", "bar", "--t-end", "1e5", "--out", str(slow)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while proc.poll() is None and time.monotonic() < deadline:  # until it steps
        rows = slow / "energies.csv"
        if rows.exists() and len(rows.read_text().splitlines()) > 2:
            break
        time.sleep(0.2)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    assert "interrupted by SIGTERM" in err and f"python -m fempm resume {slow}" in err
    assert json.loads((slow / "summary.json").read_text())["status"] == "interrupted"
    assert 0.0 < manifest(slow)["t"] < 1e5


def _command(ranks: int, *args: str) -> list[str]:
    """``python -m fempm ARGS``, under ``mpiexec -n ranks`` for more than one rank."""
    mpiexec = [str(Path(sys.executable).with_name("mpiexec")), "-n", str(ranks)] if ranks > 1 else []
    return [*mpiexec, sys.executable, "-m", "fempm", *args]


def _terminated(cmd: list[str], out: Path, rows: int) -> subprocess.CompletedProcess:
    """Start ``cmd`` and send SIGTERM once ``out/energies.csv`` holds ``rows`` rows (a step
    boundary nobody chose: wherever the run is then)."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    energies = out / "energies.csv"
    while proc.poll() is None and time.monotonic() < deadline:
        if energies.exists() and energies.read_bytes().count(b"\n") > rows:
            break
        time.sleep(0.02)
    proc.send_signal(signal.SIGTERM)
    stdout, stderr = proc.communicate(timeout=300)
    return subprocess.CompletedProcess(cmd, proc.returncode, stdout, stderr)


@pytest.mark.skipif(comm.size > 1, reason="starts its own processes")
# the default run: one rank, lumped (a resumed consistent run on 2 ranks: make test-all, and
# test_resumed_run_is_bit_identical_to_the_uninterrupted_one in the 2-rank pass)
@pytest.mark.parametrize(("mass", "ranks"), [("lumped", 1), pytest.param("consistent", 2, marks=pytest.mark.slow),
                                             pytest.param("lumped", 2, marks=pytest.mark.slow),
                                             pytest.param("consistent", 1, marks=pytest.mark.slow)])
def test_sigterm_then_resume_writes_what_the_uninterrupted_run_writes(tmp_path, mass, ranks):
    """`run` stopped by SIGTERM wherever it is, then `resume`: energies.csv is equal byte for
    byte to the uninterrupted run's (cmp), and so is every other output (the particle frames,
    the grid series, the collections, the summary's totals): the frame of the interrupted
    state is dropped on resume."""
    args = ["run", "disks", "--cells", "24", "--t-end", "3", "--frames", "10", "--mass", mass]
    whole, parts = tmp_path / "whole", tmp_path / "parts"
    r = subprocess.run(_command(ranks, *args, "--out", str(whole)), capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    r = _terminated(_command(ranks, *args, "--out", str(parts)), parts, rows=40)
    assert r.returncode == 143 and "interrupted by SIGTERM" in r.stderr, r.stderr
    stopped = manifest(parts)
    assert 40 <= stopped["step_count"] < json.loads((whole / "summary.json").read_text())["steps"]
    r = subprocess.run(_command(ranks, "resume", str(parts)), capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert subprocess.run(["cmp", str(whole / "energies.csv"), str(parts / "energies.csv")]).returncode == 0
    assert_same_outputs(parts, whole)


@pytest.mark.skipif(comm.size > 1, reason="starts its own processes")
def test_sigkill_then_resume_writes_what_the_uninterrupted_run_writes(tmp_path):
    """Killed with SIGKILL between two checkpoints: the collections (particles.pvd,
    grid_velocity.pvd, grid_stress.pvd) are readable as written so far, and after `resume`
    every output equals the uninterrupted run's (what was written after the checkpoint is
    dropped)."""
    args = ["run", "disks", "--cells", "24", "--t-end", "3", "--frames", "20", "--checkpoint-every", "25"]
    whole, parts = tmp_path / "whole", tmp_path / "parts"
    assert subprocess.run(_command(1, *args, "--out", str(whole)), capture_output=True, timeout=600).returncode == 0
    proc = subprocess.Popen(_command(1, *args, "--out", str(parts)), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    while proc.poll() is None and time.monotonic() < deadline:
        try:  # (the run swaps its checkpoint folders as it writes the next one)
            done = manifest(parts)["step_count"] >= 50 and (parts / "energies.csv").read_bytes().count(b"\n") > 62
        except (CheckpointError, OSError):
            done = False
        if done:
            break
        time.sleep(0.01)
    proc.kill()
    proc.wait()
    assert proc.returncode == -signal.SIGKILL
    for name in ("particles", "grid_velocity", "grid_stress"):  # the series so far, complete
        pvd = (parts / f"{name}.pvd").read_text()
        assert pvd.endswith("</VTKFile>\n") and pvd.count("<DataSet") >= 2
    r = subprocess.run(_command(1, "resume", str(parts)), capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert_same_outputs(parts, whole)


def _damage(folder: Path, kind: str) -> str:
    """Damage the checkpoint ``folder`` as ``kind`` says; returns what the message must name."""
    rank_file = folder / "rank_00000.npz"
    if kind == "truncated":
        data = rank_file.read_bytes()
        rank_file.write_bytes(data[: len(data) // 2])
        return "rank_00000.npz is truncated"
    if kind == "corrupted":
        data = bytearray(rank_file.read_bytes())
        data[len(data) // 2] ^= 0xFF
        rank_file.write_bytes(bytes(data))
        return "rank_00000.npz is corrupted"
    if kind == "missing rank file":
        rank_file.unlink()
        return "rank_00000.npz is missing"
    if kind == "manifest not JSON":
        (folder / "manifest.json").write_text("{ this is not JSON")
        return "manifest.json is not JSON"
    if kind == "manifest edited":  # a value changed by hand: the digest no longer fits
        data = json.loads((folder / "manifest.json").read_text())
        data["step_count"] += 1
        (folder / "manifest.json").write_text(json.dumps(data))
        return "manifest.json was changed after it was written"
    if kind == "manifest without keys":
        data = json.loads((folder / "manifest.json").read_text())
        del data["files"], data["monitor"]
        (folder / "manifest.json").write_text(json.dumps(data))
        return "manifest.json lacks the key(s) files, monitor"
    raise ValueError(kind)


DAMAGES = ("truncated", "corrupted", "missing rank file", "manifest not JSON", "manifest without keys", "manifest edited")


@pytest.mark.skipif(comm.size > 1, reason="starts its own processes")
def test_a_damaged_checkpoint_falls_back_on_the_one_before_or_is_one_clear_line(tmp_path):
    """Each damage of the newest checkpoint: `resume` says which file is damaged and how,
    continues from checkpoint.prev, and writes the energies of the uninterrupted run to the
    new end. Both damaged: exit 2 and one line naming the file, no traceback."""
    import shutil

    cmd = ["run", "disks", "--cells", "10", "--checkpoint-every", "10"]
    ran = tmp_path / "ran"
    r = subprocess.run(_command(1, *cmd, "--t-end", "0.5", "--out", str(ran)), capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    previous = json.loads((ran / "checkpoint.prev" / "manifest.json").read_text())
    assert previous["step_count"] < manifest(ran)["step_count"] and (ran / "checkpoint.prev").is_dir()
    whole = tmp_path / "whole"
    assert subprocess.run(_command(1, *cmd, "--t-end", "0.6", "--out", str(whole)), capture_output=True,
                          timeout=300).returncode == 0
    for kind in DAMAGES:
        out = tmp_path / kind.replace(" ", "-")
        shutil.copytree(ran, out)
        named = _damage(out / "checkpoint", kind)
        r = subprocess.run(_command(1, "resume", str(out), "--t-end", "0.6"), capture_output=True, text=True,
                           timeout=300)
        assert r.returncode == 0, (kind, r.stderr)
        assert f"checkpoint/{named}" in r.stderr and "continuing from checkpoint.prev/" in r.stderr, (kind, r.stderr)
        assert f"step {previous['step_count']}" in r.stderr
        assert (out / "energies.csv").read_bytes() == (whole / "energies.csv").read_bytes(), kind
        if kind != DAMAGES[0]:
            continue
        # the one before damaged as well: nothing to continue from (the same path for every damage)
        shutil.rmtree(out)
        shutil.copytree(ran, out)
        _damage(out / "checkpoint", kind)
        _damage(out / "checkpoint.prev", "truncated")
        r = subprocess.run(_command(1, "resume", str(out), "--t-end", "0.7"), capture_output=True, text=True,
                           timeout=300)
        assert r.returncode == 2 and "Traceback" not in r.stderr, (kind, r.stderr)
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and "is damaged" in lines[0] and "checkpoint.prev/rank_00000.npz is truncated" in lines[0]


def test_a_checkpoint_is_checked_against_the_scene_it_resumes(tmp_path):
    """Another parameter, another mass model, another mesh, a checkpoint without the velocity
    field: each a CheckpointError naming the difference; only t_end may change."""
    import dataclasses

    import dolfinx.mesh as dm

    from fempm.io.checkpoint import CheckpointError
    from fempm.particles.seeding import create_particles

    out = _folder(tmp_path, "disks")
    run(two_disks(cells=10, t_end=0.2, frames=2), out, progress=False, checkpoint_every=5)
    with pytest.raises(CheckpointError, match=r"parameter E is 1000.0 in the checkpoint, 2000.0 here"):
        run(two_disks(cells=10, t_end=0.3, frames=2, E=2000.0), out, progress=False, resume=True)
    with pytest.raises(CheckpointError, match=r"option mass is 'lumped' in the checkpoint, 'consistent' here"):
        run(two_disks(cells=10, t_end=0.3, frames=2, mass="consistent"), out, progress=False, resume=True)
    with pytest.raises(CheckpointError, match=r"health limit j_min is 0.01 in the checkpoint, 0.001 here"):
        scene = two_disks(cells=10, t_end=0.3, frames=2)
        run(dataclasses.replace(scene, health=dataclasses.replace(scene.health, j_min=1e-3)), out, progress=False,
            resume=True)
    scene = two_disks(cells=10, t_end=0.3, frames=2)
    other = dm.create_unit_square(comm, 10, 10, dm.CellType.triangle)  # the same parameters, another mesh
    moved = dataclasses.replace(scene, mesh=other, particles=create_particles(other, 4, density=1000.0))
    with pytest.raises(CheckpointError, match=r"written on another mesh \(digest quadrilateral:100:.* this mesh "
                                              r"triangle:200:"):
        run(moved, out, progress=False, resume=True)
    resumed = run(two_disks(cells=10, t_end=0.3, frames=2), out, progress=False, resume=True)
    assert resumed["status"] == "completed" and resumed["t_end"] == 0.3


@pytest.mark.skipif(comm.size > 1, reason="rewrites one rank file")
def test_a_checkpoint_without_a_field_the_run_needs_is_refused(tmp_path):
    """A rank file (and manifest) without ``field:v``: the solver would start it at v = 0
    and report "completed"; it is a CheckpointError naming the field."""
    import hashlib

    from fempm.io.checkpoint import CheckpointError, manifest_digest

    out = tmp_path / "disks"
    run(two_disks(cells=10, t_end=0.2, frames=2), out, progress=False, checkpoint_every=5)
    folder = out / "checkpoint"
    rank = folder / "rank_00000.npz"
    with np.load(rank) as z:
        arrays = {k: z[k] for k in z.files if k != "field:v"}
    np.savez(rank, **arrays)
    data = json.loads((folder / "manifest.json").read_text())
    del data["fields"]["v"]
    data["files"]["rank_00000.npz"] = {"bytes": rank.stat().st_size, "sha256": hashlib.sha256(rank.read_bytes()).hexdigest()}
    data["digest"] = manifest_digest(data)  # a whole checkpoint without the field, not a damaged one
    (folder / "manifest.json").write_text(json.dumps(data))
    with pytest.raises(CheckpointError, match=r"lacks the particle field\(s\) v"):
        run(two_disks(cells=10, t_end=0.3, frames=2), out, progress=False, resume=True)


def _watched(name: str, c=comm):
    """A small scene of each kind with a watch (its results come from the watch's history)."""
    from fempm.scenes.footing import footing
    from fempm.scenes.impact import disk_impact
    from fempm.scenes.incline import incline
    from fempm.scenes.silo import silo

    return {"footing": lambda: footing(cells=4, depth=0.05, comm=c),
            "silo": lambda: silo(cells=3, t_end=0.25, frames=2, comm=c),
            "incline": lambda: incline(body="disk", cells=4, t_end=0.2, frames=2, comm=c),
            "impact": lambda: disk_impact(cells=12, t_end=0.03, frames=2, comm=c)}[name]()


#: each watched scene's own results in its summary
WATCHED = {"footing": ("bearing_pressure", "bearing_ratio"), "silo": ("discharge_rate", "hopper_mass"),
           "incline": ("acceleration",), "impact": ("penetration",)}


@pytest.mark.parametrize("name", sorted(WATCHED))
@pytest.mark.parallel(only=("footing", "silo"))
def test_a_resumed_scene_keeps_its_watch(tmp_path, name):
    """A scene whose results come from its watch's history (a footing's pressure curve, a
    silo's hopper mass, the incline's track, the impact's deepest overlap), interrupted half
    way and resumed: every output equals the uninterrupted run's, the summary's results
    included (the watch's state is in the checkpoint)."""
    whole, parts = _folder(tmp_path, "whole"), _folder(tmp_path, "parts")
    done = run(_watched(name), whole, progress=False)
    half = 0.5 * done["t_end"]
    with pytest.raises(RunInterrupted):
        run(_watched(name), parts, progress=False, checkpoint_every=100000, callback=_interrupt_at(half))
    assert 0.0 < manifest(parts)["t"] < done["t_end"] and manifest(parts)["watch"]
    resumed = run(_watched(name), parts, progress=False, resume=True)
    for key in WATCHED[name]:
        assert json.dumps(resumed[key]) == json.dumps(done[key]), (key, resumed[key], done[key])
    if comm.rank == 0:
        assert_same_outputs(parts, whole)


@pytest.mark.skipif(comm.size > 1, reason="starts its own processes")
def test_a_footing_killed_then_resumed_reports_the_whole_pressure_curve(tmp_path):
    """SIGKILL between two checkpoints of `run footing`, then `resume`: the summary's bearing
    pressure is the uninterrupted run's (it was computed from the resumed part only)."""
    args = ["run", "footing", "--cells", "4", "--depth", "0.05", "--checkpoint-every", "40"]
    whole, parts = tmp_path / "whole", tmp_path / "parts"
    assert subprocess.run(_command(1, *args, "--out", str(whole)), capture_output=True, timeout=600).returncode == 0
    proc = subprocess.Popen(_command(1, *args, "--out", str(parts)), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    while proc.poll() is None and time.monotonic() < deadline:
        if (parts / "checkpoint").exists() and manifest(parts)["step_count"] >= 120:
            break
        time.sleep(0.01)
    proc.kill()
    proc.wait()
    assert proc.returncode == -signal.SIGKILL
    r = subprocess.run(_command(1, "resume", str(parts)), capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    a, b = (json.loads((f / "summary.json").read_text()) for f in (parts, whole))
    assert a["bearing_pressure"] == b["bearing_pressure"] and a["steps"] == b["steps"]
    assert_same_outputs(parts, whole)
