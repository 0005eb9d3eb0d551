"""Command line: ``python -m fempm study mapping [--full] [--out DIR]``."""

from __future__ import annotations

import argparse
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m fempm", description="fempm: MPM on DOLFINx meshes")
    sub = parser.add_subparsers(dest="command", required=True)
    study = sub.add_parser("study", help="run a study and write its tables and figures")
    study.add_argument("name", choices=["mapping"])
    study.add_argument("--full", action="store_true", help="more mesh sizes and particle densities")
    study.add_argument("--sizes", type=int, nargs="+", help="cells per side (default 8 16 32; --full: 8 ... 128)")
    study.add_argument("--ppc", type=int, nargs="+", help="particles per cell (default 4 9; --full: 1 4 9 16)")
    study.add_argument("--out", type=Path, default=None, help="output folder (default output/study-NAME)")
    args = parser.parse_args(argv)

    import fempm  # noqa: F401  (dolfinx_solver before dolfinx)

    if args.command == "study" and args.name == "mapping":
        from fempm.studies import mapping

        sizes = args.sizes or ((8, 16, 32, 64, 128) if args.full else (8, 16, 32))
        ppcs = args.ppc or ((1, 4, 9, 16) if args.full else (4, 9))
        out = args.out or Path("output/study-mapping")
        mapping.run(sizes=sizes, ppcs=ppcs, out=out)
        from mpi4py import MPI

        if MPI.COMM_WORLD.rank == 0:
            print(f"wrote {out}/mapping.csv, mapping.md, mapping.png")
    return 0
