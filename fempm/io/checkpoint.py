r"""Checkpoint and restart of a :func:`fempm.scene.run`.

A checkpoint is the folder ``OUT/checkpoint/``:

* ``rank_NNNNN.npz``, one per rank: the rank's particles with every array (``x``, ``cells``,
  ``X``, ``mass``, ``volume``, ``ids`` and each field as ``field:NAME``; numpy's own format,
  exact, readable with ``numpy.load``), and the solver's per-rank warm starts (the last grid
  velocity; with consistent mass the last grid acceleration);
* ``manifest.json``: the time, the step count, the number of ranks, the scene's name,
  parameters, options and health limits, a digest of the mesh (:func:`mesh_digest`), the
  particle fields and their shapes, each rank file's size and SHA-256, how to rebuild the
  scene (the command line's scene and options), the solver's and the run-health monitor's
  accumulated state, the scene watch's history (:class:`fempm.scene.Recorder`: a footing's
  pressure curve, a silo's hopper mass), the writer's frame count, and the SHA-256 of all of
  that (``digest``: a manifest edited by hand is damaged, like a rank file whose digest differs).

It is written atomically and the one before is kept: every rank writes into
``checkpoint.tmp/``, rank 0 writes the manifest last, then swaps the folders
(``checkpoint`` -> ``checkpoint.prev``, ``checkpoint.tmp`` -> ``checkpoint``). A continued run
reads the newest checkpoint that is complete and intact (its manifest is JSON with every key,
every rank file is there with the size and digest the manifest gives); when the newest is
damaged it says so, names the file and what is wrong with it, and continues from the one
before (:func:`choose`). A checkpoint that does not fit the scene it is restored into (another
scene, parameter, option, health limit, mesh, particle count, or fields) is a
:class:`CheckpointError` naming the difference; only ``t_end`` may change.

Restoring on the same number of ranks puts every array back as it was, in the same order, so
that the continued run is bit for bit the uninterrupted one. With consistent mass the compiled
step's kept systems go in too
(:meth:`fempm.stepping.consistent.ConsistentNodalMass.checkpoint_state`: the sparsity's cells,
the matrix values each preconditioner was set up from, the warm starts and counters), and the
preconditioners are set up again from those values. On another number of ranks the particles
are distributed anew by their cells (:class:`fempm.particles.Particles`) and the warm starts
and kept systems are dropped: results agree to round-off.

Every component with a state of its own shares one protocol, and this module calls only that:
``state_dict()`` returns the state (JSON values; a solver's rank-local arrays under
``"arrays"``, which go into the rank files) and ``load_state_dict(state)`` puts it back: the
solver (:meth:`fempm.stepping.ExplicitSolver.state_dict`, which holds its step record, its
removed particles' account and its colliders' state, each by their own ``state_dict``), the
run-health monitor (:meth:`fempm.stepping.health.HealthMonitor.state_dict`) and the scene's
watch (:class:`fempm.scene.Recorder`); the writer's frame count is ``RunWriter.state_dict``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import shutil
import sys
import zipfile
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fempm.meshes.geometry import coordinate_map
from fempm.particles.particle_set import Particles
from fempm.io.stops import RunInterrupted, requested, stop_requests  # noqa: F401 (fempm.io.checkpoint names them)

__all__ = ["FOLDER", "FORMAT", "CheckpointError", "RunInterrupted", "check_fields", "choose", "manifest",
           "manifest_digest", "mesh_digest", "requested", "restore_particles", "restore_solver", "restore_watch",
           "stop_requests", "write"]

FORMAT = 3
FOLDER = "checkpoint"
#: the checkpoint before the newest, kept as a fallback
PREVIOUS = FOLDER + ".prev"
#: the manifest keys a checkpoint needs
MANIFEST_KEYS = ("format", "ranks", "t", "step_count", "scene", "params", "options", "health", "mesh", "fields",
                 "files", "particles", "solver", "monitor", "writer", "rebuild", "watch", "digest")


class CheckpointError(RuntimeError):
    """A checkpoint that is missing, damaged or does not fit the scene it is restored into."""


def _jsonable(v):
    """numpy values as plain numbers and lists; anything else by its repr."""
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    return repr(v)


def _plain(data):
    """``data`` as it reads back from JSON (tuples as lists, numpy numbers as plain ones)."""
    return json.loads(json.dumps(data, default=_jsonable))


def mesh_digest(mesh) -> str:
    """A digest of the mesh's geometry and topology that does not depend on its partition or
    numbering: the cell type, the number of cells and the sum (mod :math:`2^{64}`) of a hash of
    each cell's node coordinates (their exact bits, nodes in lexicographic order). Collective."""
    tdim = mesh.topology.dim
    owned = mesh.topology.index_map(tdim).size_local
    xc = mesh.geometry.x[np.asarray(coordinate_map(mesh)[1])[:owned]] + 0.0  # (cells, nodes, 3); -0.0 -> 0.0
    bits = np.ascontiguousarray(xc).view(np.uint64)
    order = np.lexsort((bits[..., 2], bits[..., 1], bits[..., 0]), axis=-1)
    words = np.take_along_axis(bits, order[..., None], axis=1).reshape(owned, -1)
    h = np.full(owned, 0x9E3779B97F4A7C15, dtype=np.uint64)
    with np.errstate(over="ignore"):
        for w in words.T:  # a multiply-xorshift hash of each cell's words
            h = (h ^ w) * np.uint64(0xBF58476D1CE4E5B9)
            h ^= h >> np.uint64(31)
        total = np.array([np.sum(h, dtype=np.uint64), owned], dtype=np.uint64)
    mesh.comm.Allreduce(MPI.IN_PLACE, total, op=MPI.SUM)
    return f"{mesh.topology.cell_name()}:{int(total[1])}:{int(total[0]):016x}"


def _fields(p) -> dict:
    """The particles' fields: name -> [trailing shape, dtype]."""
    return {k: [list(v.shape[1:]), v.dtype.str] for k, v in p.fields.items()}


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 22), b""):
            digest.update(block)
    return digest.hexdigest()


def write(out: Path, scene, solver, monitor, writer_state: dict, rebuild: dict | None = None) -> Path:
    """Write the run's state into ``out/checkpoint/`` (collective, atomic, the one before kept
    as ``checkpoint.prev``); returns its path."""
    comm = solver.particles.comm
    out = Path(out)
    tmp, final, previous = out / (FOLDER + ".tmp"), out / FOLDER, out / PREVIOUS
    if comm.rank == 0:
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
    comm.Barrier()
    p = solver.particles
    arrays = {"x": p.x, "cells": p.cells, "X": p.X, **p.data_arrays()}
    state = solver.state_dict()  # its rank's arrays: e.g. the consistent step's warm starts and kept systems
    arrays.update({f"solver:{k}": v for k, v in state.pop("arrays").items()})
    t, step_count = state.pop("t"), state.pop("step_count")
    name = f"rank_{comm.rank:05d}.npz"
    error, record = None, None
    try:
        with open(tmp / name, "wb") as fh:
            np.savez(fh, **arrays)
        record = {"bytes": (tmp / name).stat().st_size, "sha256": _sha256(tmp / name)}
    except OSError as e:
        error = f"rank {comm.rank}: {e}"
    gathered = comm.allgather((name, record, error))
    errors = [e for _, _, e in gathered if e]
    if errors:
        raise CheckpointError(f"writing the checkpoint in {tmp} failed: {'; '.join(errors)}")
    manifest = {
        "format": FORMAT, "ranks": comm.size, "t": t, "step_count": step_count,
        "t_end": scene.t_end, "scene": scene.name, "params": scene.params, "rebuild": rebuild,
        "options": _options(scene), "health": scene.health.asdict(), "mesh": mesh_digest(scene.mesh),
        "fields": _fields(p), "files": {n: r for n, r, _ in gathered},
        "particles": p.num_global,
        "solver": state,
        "monitor": monitor.state_dict(),
        "writer": writer_state,
        "watch": scene.watch.state_dict() if callable(getattr(scene.watch, "state_dict", None)) else None,
    }
    manifest = _plain(manifest)
    manifest["digest"] = manifest_digest(manifest)
    if comm.rank == 0:
        (tmp / "manifest.json").write_text(json.dumps(manifest, indent=1, default=_jsonable))
        if final.exists():
            shutil.rmtree(previous, ignore_errors=True)
            final.rename(previous)
        tmp.rename(final)
    comm.Barrier()
    return final


def manifest_digest(data: dict) -> str:
    """The SHA-256 of a manifest's entries but its ``digest`` (keys sorted, as JSON)."""
    body = {k: v for k, v in data.items() if k != "digest"}
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()


def _options(scene) -> dict:
    """The scene's step options as given (numbers, names; others by their repr)."""
    values = {f.name: getattr(scene.options, f.name) for f in dataclasses.fields(scene.options)}
    if scene.outside != "raise":  # (checkpoints from before the option compare equal)
        values["outside"] = scene.outside
    return {k: v if isinstance(v, (bool, int, float, str, type(None))) else repr(v) for k, v in values.items()}


def _problem(path: Path) -> tuple[dict | None, str | None]:
    """(manifest, None) of an intact checkpoint folder, else (None, what is wrong with it)."""
    where = f"{path.name}/manifest.json"
    if not (path / "manifest.json").is_file():
        return None, f"{where} is missing" if path.exists() else f"{path.name}/ is missing"
    try:
        data = json.loads((path / "manifest.json").read_text())
    except (ValueError, UnicodeDecodeError) as e:
        return None, f"{where} is not JSON ({e})"
    except OSError:  # renamed away since: a run writing its next checkpoint (a reader polling it)
        return None, f"{where} is missing"
    if not isinstance(data, dict):
        return None, f"{where} is not a JSON object"
    if data.get("format") != FORMAT:
        return None, (f"{where} has format {data.get('format')!r}, this fempm reads format {FORMAT} (a checkpoint "
                      "of another fempm version)")
    missing = [k for k in MANIFEST_KEYS if k not in data]
    if missing:
        return None, f"{where} lacks the key(s) {', '.join(missing)}"
    if data["digest"] != manifest_digest(data):
        return None, f"{where} was changed after it was written (its SHA-256 differs from its digest)"
    for name, record in sorted(data["files"].items()):
        f = path / name
        if not f.is_file():
            return None, f"{path.name}/{name} is missing"
        size = f.stat().st_size
        if size != record["bytes"]:
            return None, f"{path.name}/{name} is truncated or overwritten ({size} bytes, the manifest says {record['bytes']})"
        if _sha256(f) != record["sha256"]:
            return None, f"{path.name}/{name} is corrupted (its SHA-256 differs from the manifest's)"
    return data, None


def choose(out: Path, comm: MPI.Comm = MPI.COMM_SELF) -> tuple[Path, dict, str | None]:
    """(folder, manifest, note) of the newest intact checkpoint in ``out``: ``checkpoint``, else
    ``checkpoint.prev`` (``note`` then says what is wrong with the newest); a
    :class:`CheckpointError` naming the damaged file and what is wrong with it when neither is
    usable. Rank 0 reads and checks the files; every rank of ``comm`` gets its answer."""
    answer = None
    if comm.rank == 0:
        out = Path(out)
        problems = []
        for name in (FOLDER, PREVIOUS):
            data, problem = _problem(out / name)
            if data is not None:
                note = None if not problems else (f"{problems[0]}; continuing from {name}/ (t = {data['t']:.6g}, step "
                                                  f"{data['step_count']})")
                answer = (str(out / name), data, note)
                break
            problems.append(problem)
        if answer is None:
            damaged = [p for p in problems if not p.endswith("/ is missing")]
            if not damaged:
                answer = (f"no checkpoint in {str(out)!r} (a run writes one with checkpoint_every / "
                          "--checkpoint-every, and when it is interrupted)")
            else:
                answer = (f"the checkpoint in {str(out)!r} is damaged: {'; '.join(damaged)}"
                          + ("; there is no earlier checkpoint to continue from" if len(damaged) == 1 else ""))
    answer = comm.bcast(answer, root=0) if comm.size > 1 else answer
    if isinstance(answer, str):
        raise CheckpointError(answer)
    return Path(answer[0]), answer[1], answer[2]


def manifest(out: Path) -> dict:
    """The manifest of the checkpoint in ``out`` that a continued run would use (:func:`choose`)."""
    return choose(out)[1]


def _differences(data: dict, scene) -> list[str]:
    """What differs between a checkpoint and the scene it is restored into (t_end may)."""
    out = []
    if data["scene"] != scene.name:
        return [f"it is of scene {data['scene']!r}, not {scene.name!r}"]
    for what, saved, here in (("parameter", data["params"], _plain(scene.params)),
                              ("option", data["options"], _plain(_options(scene))),
                              ("health limit", data["health"], _plain(scene.health.asdict()))):
        for k in sorted(set(saved) | set(here)):
            if k != "t_end" and saved.get(k, "(not set)") != here.get(k, "(not set)"):
                out.append(f"{what} {k} is {saved.get(k, '(not set)')!r} in the checkpoint, "
                           f"{here.get(k, '(not set)')!r} here")
    return out


def _load(path: Path, data: dict) -> dict:
    """The arrays of a rank file, checked against the manifest's fields."""
    try:
        with np.load(path) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
        raise CheckpointError(f"{path.parent.name}/{path.name} cannot be read: {e}") from None
    n = len(arrays.get("x", ()))
    for name, (trailing, _dtype) in data["fields"].items():
        a = arrays.get(f"field:{name}")
        if a is None:
            raise CheckpointError(f"{path.parent.name}/{path.name} lacks the particle field {name!r}")
        if list(a.shape) != [n, *trailing]:
            raise CheckpointError(f"{path.parent.name}/{path.name}: field {name!r} has shape {a.shape}, expected "
                                  f"{tuple([n, *trailing])}")
    for name in ("x", "cells", "X", "mass", "volume", "ids"):
        if name not in arrays or len(arrays[name]) != n:
            raise CheckpointError(f"{path.parent.name}/{path.name} lacks the particle array {name!r} or has the wrong "
                                  "number of rows")
    return arrays


def restore_particles(out: Path, scene, comm: MPI.Comm) -> tuple[dict, dict]:
    """Put the checkpoint's particles into ``scene`` (before its solver is built); returns
    (manifest, this rank's solver arrays: warm starts, empty on another number of ranks).
    Collective; the checkpoint is checked against the scene first (:func:`choose`)."""

    path, data, note = choose(out, comm)
    if note is not None and comm.rank == 0:
        print(f"fempm: {note}", file=sys.stderr)
    differences = _differences(data, scene)
    if differences:
        raise CheckpointError(f"the checkpoint in {str(out)!r} does not fit this run: {'; '.join(differences)} "
                              "(only t_end may change)")
    digest = mesh_digest(scene.mesh)
    if digest != data["mesh"]:
        raise CheckpointError(f"the checkpoint in {str(out)!r} was written on another mesh (digest {data['mesh']}, "
                              f"this mesh {digest})")
    if comm.size == data["ranks"]:  # the same layout: every array back in place and order
        arrays = _load(path / f"rank_{comm.rank:05d}.npz", data)
        solver_arrays = {k[7:]: arrays.pop(k) for k in list(arrays) if k.startswith("solver:")}
        scene.particles.set_arrays(arrays)
    else:  # read a share of the files, then let each particle go to the rank owning its cell
        parts = [_load(path / f"rank_{r:05d}.npz", data) for r in range(comm.rank, data["ranks"], comm.size)]
        if not parts:  # more ranks than files: none here, of the right shapes and types
            parts = [{k: v[:0] for k, v in _load(path / "rank_00000.npz", data).items()}]
        merged = {k: np.concatenate([q[k] for q in parts]) for k in parts[0] if not k.startswith("solver:")}
        d = scene.mesh.geometry.dim
        fields = {k[6:]: v for k, v in merged.items() if k.startswith("field:")}
        scene.particles = Particles(scene.mesh, merged["x"].reshape(-1, d), merged["mass"], merged["volume"],
                                    fields=fields, ids=merged["ids"], locator=scene.particles.locator)
        solver_arrays = {}
    if scene.particles.num_global != data["particles"]:
        raise CheckpointError(f"restored {scene.particles.num_global} particles, the checkpoint holds {data['particles']}")
    return data, solver_arrays


def check_fields(data: dict, particles, comm: MPI.Comm) -> None:
    """Every field the solver built on the restored particles has was in the checkpoint (a
    field it had to create, e.g. the velocity, would start from its default). Collective (the
    fields are the same on every rank)."""
    missing = sorted(set(particles.fields) - set(data["fields"]))
    if missing:
        raise CheckpointError(f"the checkpoint lacks the particle field(s) {', '.join(missing)} that this run needs")


def restore_watch(watch, data: dict) -> None:
    """Put the checkpoint's history of the scene's ``watch`` back (a watch without
    ``load_state_dict`` keeps none).

    Raises:
        CheckpointError: A checkpoint without the state of a watch that keeps one, or with the
            state of one where this scene's watch keeps none.
    """
    state = data["watch"]
    loads = callable(getattr(watch, "load_state_dict", None))
    if loads != (state is not None):
        raise CheckpointError("the checkpoint holds " + ("no" if state is None else "a") + " scene watch state; this "
                              "scene's watch " + ("keeps one" if loads else "keeps none"))
    if loads:
        try:
            watch.load_state_dict(state)
        except ValueError as e:
            raise CheckpointError(str(e)) from None


def restore_solver(solver, monitor, data: dict, solver_arrays: dict) -> None:
    """Put the checkpoint's solver and run-health state into a solver built on the restored
    particles (and its monitor), through their ``load_state_dict`` (collective: on another
    number of ranks every rank passes no solver arrays)."""
    solver.load_state_dict({**data["solver"], "t": data["t"], "step_count": data["step_count"],
                            "arrays": solver_arrays})
    try:
        monitor.load_state_dict(data["monitor"])
    except ValueError as e:
        raise CheckpointError(str(e)) from None
