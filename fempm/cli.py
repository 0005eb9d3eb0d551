"""Command line.

    python -m fempm study mapping [--full] [--domains point gimp cpdi1 cpdi2] [--out DIR]
    python -m fempm study particle-basis [--out DIR]
    python -m fempm study convergence [--quick] [--problems NAME ...] [--out DIR]
    python -m fempm study stability [--quick] [--cases NAME ...] [--out DIR]
    python -m fempm study error-vs-time [--quick] [--problems NAME ...] [--out DIR]
    python -m fempm study scenes [--quick] [--problems NAME ...] [--out DIR]
    python -m fempm study all [--out DIR]   (the quick version of every study, into DIR/study-NAME)
    python -m fempm run SCENE [--out DIR] [--overwrite] [--force] [--checkpoint-every N] [--frame-format F]
                              [--option value ...] [-petsc_option value ...]
    python -m fempm resume OUT [--t-end T] [--checkpoint-every N]
    (run, resume, study: [--mesh-cache DIR | --no-mesh-cache], where gmsh's meshes are kept)
    python -m fempm run --help          (the scenes, a line each)
    python -m fempm --version

Scene options are the keyword arguments of the scene builders in :mod:`fempm.scenes`
(``python -m fempm run disks --help`` lists them). A usage error (an unknown scene or option,
a value of the wrong type or out of range, an output folder that cannot be created) prints one
line and exits with code 2; a run stopped by its health limits or a failed step exits with 3;
a run stopped by SIGTERM or SIGINT writes a checkpoint and exits with 128 + the signal
(``resume`` continues it, :mod:`fempm.io.checkpoint`).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

from mpi4py import MPI

from fempm import __version__
from fempm.abort import abort_on_error
from fempm.petsc import temporary_options
from fempm.io.checkpoint import CheckpointError, choose
from fempm.io.stops import RunInterrupted
from fempm.io.writers import (
    FRAME_FORMATS,
    OUTPUT_LIMIT,
    OutputFolderError,
    OutputSizeError,
    OutputWriteError,
)
from fempm.meshes.cache import CACHE_ENV, set_mesh_cache
from fempm.particles.location import OutsideMeshError
from fempm.run_options import (UsageError, health_descriptions, health_options, option_descriptions, petsc_options,
                                scene_options, stepping_options, with_stepping)
from fempm.scene.loop import run
from fempm.scenes import SCENES
from fempm.stepping.health import Health
from fempm.stepping.options import SimulationError
from fempm.studies import convergence, error_vs_time, mapping, particle_basis, scenes, stability
from fempm.studies.harness import Provenance
from fempm.transfer.mapping import SingularMassError

__all__ = ["UsageError", "main"]


def main(argv: list[str] | None = None) -> int:
    """The command line; under MPI an exception on one rank ends every rank
    (:func:`fempm.abort.abort_on_error`; usage errors, the same on every rank, exit with 2)."""

    try:
        with abort_on_error():
            return _main(argv)
    except UsageError as e:
        if MPI.COMM_WORLD.rank == 0:
            print(e, file=sys.stderr)
        return 2


#: the studies of ``python -m fempm study NAME`` (``all``: the quick version of each)
STUDIES = ("mapping", "particle-basis", "convergence", "stability", "error-vs-time", "scenes")


def _parser() -> argparse.ArgumentParser:
    """The command line's parser: ``study``, ``run`` (its scene options parsed later,
    :func:`_scene_options`) and ``resume``."""
    parser = argparse.ArgumentParser(prog="python -m fempm", description="fempm: MPM on DOLFINx meshes", allow_abbrev=False)
    parser.add_argument("--version", action="version", version=f"fempm {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    study = sub.add_parser("study", help="run a study and write its tables and figures", allow_abbrev=False)
    study.add_argument("name", choices=[*STUDIES, "all"], help="a study, or all: the quick version of every one")
    study.add_argument("--full", action="store_true", help="mapping: more mesh sizes and particle densities")
    study.add_argument("--quick", action="store_true",
                       help="convergence, stability, error-vs-time: fewer configurations and smaller sizes")
    study.add_argument("--problems", nargs="+", metavar="NAME",
                       help="convergence, error-vs-time: a subset of the problems; scenes: scenes or scene/variant series")
    study.add_argument("--cases", nargs="+", metavar="NAME", help="stability: a subset of the cases")
    study.add_argument("--sizes", type=int, nargs="+", help="cells per side (default 8 16 32; --full: 8 ... 128)")
    study.add_argument("--ppc", type=int, nargs="+", help="particles per cell (default 4 9; --full: 1 4 9 16)")
    study.add_argument("--domains", nargs="+", default=["point"], metavar="DOMAIN",
                       help="mapping: particle domains point, gimp, cpdi1, cpdi2 (default point)")
    study.add_argument("--out", type=Path, default=None,
                       help="output folder (default output/study-NAME; all: the folder of the study-NAME folders)")
    runp = sub.add_parser("run", help="run a scene, writing outputs and a JSON summary", add_help=False, allow_abbrev=False)
    runp.add_argument("scene", nargs="?")
    runp.add_argument("--out", type=Path, default=None, help="output folder (default output/SCENE)")
    runp.add_argument("-h", "--help", action="store_true")
    runp.add_argument("--checkpoint-every", type=int, default=None, metavar="N",
                      help="write the full state to OUT/checkpoint every N steps and at the end")
    runp.add_argument("--overwrite", action="store_true", help="replace the outputs of an earlier run in OUT")
    runp.add_argument("--frame-format", choices=list(FRAME_FORMATS), default="vtkhdf",
                      help="particle frames: vtkhdf (one file per frame for all ranks, default) or vtu (VTK XML, a "
                           "piece per rank)")
    runp.add_argument("--force", action="store_true",
                      help="write the frames even when they would exceed 2 GB (else the run stops before it starts)")
    _cache_options(runp)
    resume = sub.add_parser("resume", help="continue a run from the checkpoint in its output folder", allow_abbrev=False)
    resume.add_argument("out", type=Path, help="the output folder of the run")
    resume.add_argument("--t-end", type=float, default=None, help="run to this time (default: the run's own t_end)")
    resume.add_argument("--checkpoint-every", type=int, default=None, metavar="N",
                        help="checkpoint every N steps (default: as the run did)")
    _cache_options(resume)
    _cache_options(study)
    return parser


def _cache_options(parser: argparse.ArgumentParser) -> None:
    """``--mesh-cache DIR`` and ``--no-mesh-cache`` (:mod:`fempm.meshes.cache`)."""
    cache = parser.add_mutually_exclusive_group()
    cache.add_argument("--mesh-cache", type=Path, default=None, metavar="DIR",
                       help=f"keep the meshes gmsh makes in DIR (default ${CACHE_ENV}, else ~/.cache/fempm)")
    cache.add_argument("--no-mesh-cache", action="store_true", help="make every gmsh mesh anew, keep none")


def _use_cache(args) -> None:
    if args.no_mesh_cache:
        set_mesh_cache(None)
    elif args.mesh_cache is not None:
        set_mesh_cache(args.mesh_cache)


def _main(argv: list[str] | None) -> int:
    parser = _parser()
    args, rest = parser.parse_known_args(argv)
    if args.command != "run" and rest:
        parser.error(f"unrecognized arguments: {' '.join(rest)}")
    _use_cache(args)
    if args.command == "run":
        return _run(args, rest)
    if args.command == "resume":
        return _resume(args)
    try:
        return _study(args)
    except ValueError as e:  # a study's options that do not fit
        parser.error(str(e))


def _study(args) -> int:
    """``python -m fempm study NAME``: run the study and say what it wrote; ``all``: the quick
    version of every study, each into ``OUT/study-NAME`` (default ``output/``)."""
    if args.name == "all":
        given = [f"--{k}" for k in ("full", "problems", "cases", "sizes", "ppc") if getattr(args, k)]
        if given:
            raise ValueError(f"study all runs the quick version of every study; it takes --out only, not {given[0]}")
        args.quick = True
        folders = {name: (args.out or Path("output")) / f"study-{name}" for name in STUDIES}
    else:
        folders = {args.name: args.out or Path(f"output/study-{args.name}")}
    provenance = Provenance.now()
    for name, out in folders.items():
        written = _STUDY_RUNS[name](args, out, provenance)
        if MPI.COMM_WORLD.rank == 0:
            print(f"wrote {out}/: {written}, provenance.json")
    return 0


def _particle_basis(args, out: Path, provenance: Provenance) -> str:
    if MPI.COMM_WORLD.rank == 0:  # dense operators on small bodies: one rank
        particle_basis.run(out, provenance=provenance)
    return "properties.md, properties.csv, particle_basis_*.png"


def _mapping(args, out: Path, provenance: Provenance) -> str:
    sizes = args.sizes or ((8, 16, 32, 64, 128) if args.full else (8, 16, 32))
    ppcs = args.ppc or ((1, 4, 9, 16) if args.full else (4, 9))
    mapping.run(sizes=sizes, ppcs=ppcs, out=out, domains=tuple(args.domains), provenance=provenance)
    return "mapping.csv, mapping.md, mapping.png"


def _convergence(args, out: Path, provenance: Provenance) -> str:
    convergence.run(out, quick=args.quick, problems=args.problems, provenance=provenance)
    return "convergence.csv, convergence.md, convergence_*.png"


def _stability(args, out: Path, provenance: Provenance) -> str:
    stability.run_study(out, quick=args.quick, cases=args.cases, provenance=provenance)
    return "stability.csv, stability.md, stability.png"


def _error_vs_time(args, out: Path, provenance: Provenance) -> str:
    error_vs_time.run_study(out, quick=args.quick, problems=args.problems, provenance=provenance)
    return "error_vs_time.csv, error_vs_time.md, error_vs_time_*.png"


def _scenes(args, out: Path, provenance: Provenance) -> str:
    scenes.run_study(out, quick=args.quick, problems=args.problems, provenance=provenance)
    return "scenes_convergence.csv, scenes_convergence.md, scenes_*.png"


_STUDY_RUNS = {"mapping": _mapping, "particle-basis": _particle_basis, "convergence": _convergence,
               "stability": _stability, "error-vs-time": _error_vs_time, "scenes": _scenes}


def _summary(builder) -> str:
    """The first paragraph of a scene's module docstring, on one line."""
    import inspect

    doc = inspect.getmodule(builder).__doc__ or ""
    return " ".join(doc.strip().split("\n\n")[0].split())


def _run(args, rest: list[str]) -> int:
    import inspect

    if args.scene is None and args.help:
        print("python -m fempm run SCENE [--out DIR] [--option value ...]; scenes:")
        for name, builder in SCENES.items():
            print(f"  {name:12s}{_summary(builder)}")
        print("python -m fempm run SCENE --help lists the options of SCENE")
        return 0
    if args.scene is None:
        raise UsageError(f"fempm run: give a scene: {', '.join(SCENES)} (python -m fempm run --help describes them)")
    if args.scene not in SCENES:
        raise UsageError(f"fempm run: unknown scene {args.scene!r}; scenes: {', '.join(SCENES)}")
    builder = SCENES[args.scene]
    if args.help:
        print(f"python -m fempm run {args.scene} [--out DIR] [--overwrite] [--force] [--checkpoint-every N] "
              "[--frame-format vtkhdf|vtu] [--mesh-cache DIR | --no-mesh-cache] options (defaults):")
        described = option_descriptions(builder)
        for k, v in inspect.signature(builder).parameters.items():
            if k != "comm":
                print(f"  --{k.replace('_', '-')} {v.default}  {described[k]}")
        print("stepping (every scene): --integrator explicit|implicit, --dynamics newmark|quasi-static (implicit), "
              "--steps N (fixed steps to t_end; implicit runs need it), --tangent analytic|finite-difference "
              "(implicit: the laws' own tangents or central differences), --volumetric standard|fbar, "
              "--outside raise|remove (particles that leave the mesh), --transfer flip|pic|apic|tpic|xpic (the velocity "
              "transfer; flip takes the scene's --flip blend), --xpic-order M (XPIC's series terms, default 2), "
              "--affine-cutoff C (APIC/TPIC: nodes below C of the largest mass pass their acceleration to the "
              "particles' affine matrices in proportion; default 0.01)")
        print("PETSc options (one dash, as PETSc's own): -PREFIX_option value, e.g. -fempm_implicit_ksp_type cg "
              "-fempm_implicit_pc_type gamg (the implicit step's linear solves), -fempm_step_ksp_rtol 1e-12 (the "
              "consistent mass's); for the run, kept in its checkpoint for resume")
        print("run health (fempm.stepping.health.Health; a crossed limit stops the run with exit code 3):")
        limits = health_descriptions()
        for k, v in Health().asdict().items():
            print(f"  --{k.replace('_', '-')} {v}  {limits[k]}")
        return 0
    petsc, rest = petsc_options(rest)
    health, rest = health_options(rest)
    stepping, rest = stepping_options(rest)
    options = scene_options(builder, rest)
    _check_every(args.checkpoint_every, "run")
    rebuild = {"scene": args.scene, "options": options, "health": health, "stepping": stepping,
               "checkpoint_every": args.checkpoint_every, **({"petsc": petsc} if petsc else {})}
    with temporary_options("", petsc):  # the run's own PETSc options, then gone
        scene = _build(rebuild)
        return _execute(scene, args.out or Path("output") / args.scene, args.scene,
                        checkpoint_every=args.checkpoint_every, rebuild=rebuild, overwrite=args.overwrite,
                        output_limit=None if args.force else OUTPUT_LIMIT, frame_format=args.frame_format)


def _check_every(every: int | None, command: str) -> None:
    if every is not None and every < 1:
        raise UsageError(f"fempm {command}: option --checkpoint-every expects a positive number of steps, got {every}")


def _build(rebuild: dict):
    """The scene of a command line (name, options, health limits), and a solver made of it: what
    the options cannot take together (the implicit step with the scene's colliders, absorbing
    ends, contact or frictional walls; F-bar with a law it cannot average) is a usage error
    before anything is written. Collective."""

    try:
        scene = SCENES[rebuild["scene"]](**rebuild["options"])
        scene.health = dataclasses.replace(scene.health, **rebuild["health"])
        scene = with_stepping(scene, rebuild.get("stepping", {}))
        scene.solver()
    except (ValueError, TypeError) as e:  # the builders, Health and the solver check their arguments
        raise UsageError(f"fempm run {rebuild['scene']}: {e}") from None
    return scene


def _execute(scene, out: Path, name: str, **kwargs) -> int:
    """Run (or continue) ``scene`` into ``out``; the exit code: 0 done, 3 stopped by a failed
    step or a health limit, 128 + the signal when interrupted (after a checkpoint)."""
    rank0 = MPI.COMM_WORLD.rank == 0
    try:
        run(scene, out, **kwargs)
    except (OutputFolderError, OutputSizeError, CheckpointError) as e:
        raise UsageError(f"fempm {name}: {e}") from None
    except (SimulationError, SingularMassError, OutsideMeshError) as e:
        if rank0:
            print(f"\nfempm run {name}: aborted: {e}\n(summary and the failing state in {out})", file=sys.stderr)
        return 3
    except OutputWriteError as e:
        if rank0:
            print(f"\nfempm run {name}: failed: {e}\n(summary in {out})", file=sys.stderr)
        return 1
    except RunInterrupted as e:
        if rank0:
            print(f"\nfempm run {name}: {e}; continue with: python -m fempm resume {out}", file=sys.stderr)
        return 128 + e.signum
    if rank0:
        saved = ", checkpoint/" if kwargs.get("checkpoint_every") or kwargs.get("resume") else ""
        print(f"wrote {out}/summary.json, energies.csv, particles.pvd, grid_velocity.pvd, grid_stress.pvd, particles/, "
              f"grid/{saved}")
    return 0


def _resume(args) -> int:
    """``python -m fempm resume OUT``: rebuild the scene from the checkpoint's command line and
    continue it (to ``--t-end`` if given)."""
    try:
        data = choose(args.out, MPI.COMM_WORLD)[1]
    except (CheckpointError, OSError) as e:
        raise UsageError(f"fempm resume: {e}") from None
    rebuild = data.get("rebuild")
    if not rebuild:
        raise UsageError(f"fempm resume: the run in {str(args.out)!r} was started from Python; continue it with "
                         "fempm.scene.run(scene, out, resume=True)")
    with temporary_options("", rebuild.get("petsc", {})):  # the run's PETSc options, from its checkpoint
        return _continue(args, data, rebuild)


def _continue(args, data: dict, rebuild: dict) -> int:
    """The rest of :func:`_resume`, with the run's PETSc options set."""
    scene = _build(rebuild)
    if args.t_end is not None:
        if not 0.0 < args.t_end < float("inf"):
            raise UsageError(f"fempm resume: option --t-end expects a positive, finite time, got {args.t_end}")
        scene.t_end = args.t_end
    if scene.t_end <= data["t"]:
        raise UsageError(f"fempm resume: the run is at t = {data['t']:.6g}, past t_end = {scene.t_end:g}: give a later "
                         "--t-end")
    every = args.checkpoint_every if args.checkpoint_every is not None else rebuild.get("checkpoint_every")
    _check_every(every, "resume")
    rebuild = {**rebuild, "checkpoint_every": every}
    return _execute(scene, args.out, rebuild["scene"], checkpoint_every=every, resume=True, rebuild=rebuild)
