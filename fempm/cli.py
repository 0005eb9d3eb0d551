"""Command line.

    python -m fempm study mapping [--full] [--domains point gimp cpdi1 cpdi2] [--out DIR]
    python -m fempm study particle-basis [--out DIR]
    python -m fempm study convergence [--quick] [--problems NAME ...] [--out DIR]
    python -m fempm run SCENE [--out DIR] [--option value ...]   (SCENE: bar, disks, cantilever, dam, block)

Scene options are the keyword arguments of the scene builders in :mod:`fempm.scenes`
(``python -m fempm run disks --help`` lists them); an unknown option is an error.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m fempm", description="fempm: MPM on DOLFINx meshes", allow_abbrev=False)
    sub = parser.add_subparsers(dest="command", required=True)
    study = sub.add_parser("study", help="run a study and write its tables and figures", allow_abbrev=False)
    study.add_argument("name", choices=["mapping", "particle-basis", "convergence"])
    study.add_argument("--full", action="store_true", help="mapping: more mesh sizes and particle densities")
    study.add_argument("--quick", action="store_true", help="convergence: fewer configurations and smaller sizes")
    study.add_argument("--problems", nargs="+", metavar="NAME", help="convergence: a subset of the problems")
    study.add_argument("--sizes", type=int, nargs="+", help="cells per side (default 8 16 32; --full: 8 ... 128)")
    study.add_argument("--ppc", type=int, nargs="+", help="particles per cell (default 4 9; --full: 1 4 9 16)")
    study.add_argument("--domains", nargs="+", default=["point"], metavar="DOMAIN",
                       help="mapping: particle domains point, gimp, cpdi1, cpdi2 (default point)")
    study.add_argument("--out", type=Path, default=None, help="output folder (default output/study-NAME)")
    runp = sub.add_parser("run", help="run a scene, writing outputs and a JSON summary", add_help=False, allow_abbrev=False)
    runp.add_argument("scene")
    runp.add_argument("--out", type=Path, default=None, help="output folder (default output/SCENE)")
    runp.add_argument("-h", "--help", action="store_true")
    args, rest = parser.parse_known_args(argv)
    if args.command != "run" and rest:
        parser.error(f"unrecognized arguments: {' '.join(rest)}")

    import fempm  # noqa: F401  (dolfinx_solver before dolfinx)

    if args.command == "run":
        return _run(args, rest)

    if args.command == "study" and args.name == "particle-basis":
        from mpi4py import MPI

        from fempm.studies import particle_basis

        out = args.out or Path("output/study-particle-basis")
        if MPI.COMM_WORLD.rank == 0:  # dense operators on small bodies: one rank
            particle_basis.run(out)
            print(f"wrote {out}/properties.md, properties.csv, particle_basis_*.png")
        return 0

    if args.command == "study" and args.name == "convergence":
        from mpi4py import MPI

        from fempm.studies import convergence

        out = args.out or Path("output/study-convergence")
        try:
            convergence.run(out, quick=args.quick, problems=args.problems)
        except ValueError as e:
            parser.error(str(e))
        if MPI.COMM_WORLD.rank == 0:
            print(f"wrote {out}/convergence.csv, convergence.md, convergence_*.png")
        return 0

    if args.command == "study" and args.name == "mapping":
        from fempm.studies import mapping

        sizes = args.sizes or ((8, 16, 32, 64, 128) if args.full else (8, 16, 32))
        ppcs = args.ppc or ((1, 4, 9, 16) if args.full else (4, 9))
        out = args.out or Path("output/study-mapping")
        mapping.run(sizes=sizes, ppcs=ppcs, out=out, domains=tuple(args.domains))
        from mpi4py import MPI

        if MPI.COMM_WORLD.rank == 0:
            print(f"wrote {out}/mapping.csv, mapping.md, mapping.png")
    return 0


def _scene_options(builder, rest: list[str]) -> dict:
    """``--name value`` pairs typed after the builder's defaults; unknown names are errors."""
    import inspect

    params = {k: v.default for k, v in inspect.signature(builder).parameters.items() if k != "comm"}
    opts = {}
    it = iter(rest)
    for flag in it:
        if not flag.startswith("--"):
            raise SystemExit(f"fempm run: expected --option value, got {flag!r}")
        name = flag[2:].replace("-", "_")
        if name not in params:
            raise SystemExit(f"fempm run: unknown option --{flag[2:]}; options: {', '.join(sorted(params))}")
        value = next(it, None)
        if value is None:
            raise SystemExit(f"fempm run: option {flag} needs a value")
        default = params[name]
        if isinstance(default, (int, float)) and not isinstance(default, bool):
            opts[name] = type(default)(value)
        elif default is None:  # an optional number (or a name)
            try:
                opts[name] = float(value)
            except ValueError:
                opts[name] = value
        else:
            opts[name] = value
    return opts


def _run(args, rest: list[str]) -> int:
    import inspect

    from mpi4py import MPI

    from fempm.scene import run
    from fempm.scenes import SCENES

    if args.scene not in SCENES:
        raise SystemExit(f"fempm run: unknown scene {args.scene!r}; scenes: {', '.join(SCENES)}")
    builder = SCENES[args.scene]
    if args.help:
        print(f"python -m fempm run {args.scene} [--out DIR] options (defaults):")
        for k, v in inspect.signature(builder).parameters.items():
            if k != "comm":
                print(f"  --{k.replace('_', '-')} {v.default}")
        return 0
    scene = builder(**_scene_options(builder, rest))
    out = args.out or Path("output") / args.scene
    run(scene, out)
    if MPI.COMM_WORLD.rank == 0:
        print(f"wrote {out}/summary.json, energies.csv, particles/, grid_velocity.bp, grid_stress.bp")
    return 0
