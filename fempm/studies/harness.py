"""What the studies share: the record of what made an output (:class:`Provenance`), the check
of the names asked for, and the sweep that runs the cases one by one, logs each and rewrites the
CSV after every run, so that a study stopped part-way keeps what it measured.

A study is a list of cases (a problem, a configuration, a size) and a function that runs one
and returns its row; :func:`sweep` runs them, and the study's report writes its Markdown with
:meth:`Provenance.line` under the title and :meth:`Provenance.write` beside it.
"""

from __future__ import annotations

import csv
import datetime
import json
import shlex
import subprocess
import sys
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

from mpi4py import MPI

__all__ = ["VENV_PYTHON", "Provenance", "chosen", "prepare", "read_rows", "sweep", "write_table"]

REPOSITORY = Path(__file__).resolve().parents[2]
#: the interpreter the docs' commands name (the virtual environment the Makefile builds)
VENV_PYTHON = ".venv/bin/python"


def _git(*args: str) -> str:
    """The output of ``git args`` in the repository, or "" where it is not a git checkout."""
    try:
        out = subprocess.run(["git", "-C", str(REPOSITORY), *args], capture_output=True, text=True, timeout=10,
                             check=True)
    except (OSError, subprocess.SubprocessError):
        return ""
    return out.stdout.strip()


def _command(argv: Sequence[str]) -> str:
    """The command line of this process as a user would type it, with the venv's Python
    (``make demo`` and ``make test`` build ``.venv``)."""
    args = shlex.join(argv[1:])
    if Path(argv[0]).name == "__main__.py" and Path(argv[0]).parent.name == "fempm":
        return f"{VENV_PYTHON} -m fempm {args}".strip()
    return f"{VENV_PYTHON} {shlex.quote(argv[0])} {args}".strip()


@dataclass(frozen=True)
class Provenance:
    """What made an output: the commit (``-dirty`` with uncommitted changes, ``unknown`` outside a
    git checkout), the command and the date (UTC).

    Args:
        commit: the short commit hash.
        command: the command line.
        date: ISO date and time, UTC.
        ranks: the number of MPI processes.
    """

    commit: str
    command: str
    date: str
    ranks: int = 1

    @classmethod
    def now(cls, command: str | None = None, comm: MPI.Comm = MPI.COMM_WORLD) -> Provenance:
        """The provenance of an output made now by this process (``command``: default its own
        command line).

        Note:
            Collective: rank 0 asks git, and every rank gets its answer.
        """
        record = None
        if comm.rank == 0:
            commit = _git("rev-parse", "--short", "HEAD") or "unknown"
            if commit != "unknown" and _git("status", "--porcelain", "--untracked-files=no"):
                commit += "-dirty"
            date = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
            record = cls(commit, command or _command(sys.argv), date, comm.size)
        return comm.bcast(record, root=0)

    def line(self) -> str:
        """One Markdown line for the top of a report."""
        ranks = f" on {self.ranks} ranks" if self.ranks > 1 else ""
        return f"Made by `{self.command}`{ranks} at commit {self.commit} on {self.date}."

    def write(self, out: Path) -> Path:
        """``provenance.json`` in the folder ``out``; returns its path."""
        path = Path(out) / "provenance.json"
        path.write_text(json.dumps(asdict(self), indent=1) + "\n")
        return path


def write_table(out: Path, name: str, rows: Sequence[dict], provenance: Provenance,
                columns: Sequence[tuple[str, str, str]]) -> None:
    """``name.csv`` (every key of the rows), ``provenance.json`` and ``name.md`` (the provenance
    line and a Markdown table) in the folder ``out``. ``columns``: the table's columns, each
    (row key, heading, format spec), e.g. ``("error_percent", "error (%)", "+.2f")``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / f"{name}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, list(rows[0]) if rows else [c for c, _, _ in columns])
        w.writeheader()
        w.writerows(rows)
    provenance.write(out)
    lines = [provenance.line(), "", "| " + " | ".join(h for _, h, _ in columns) + " |",
             "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(format(r[k], spec) for k, _, spec in columns) + " |" for r in rows]
    (out / f"{name}.md").write_text("\n".join(lines) + "\n")


def chosen(names: Iterable[str] | None, known: Sequence[str], kind: str) -> list[str]:
    """The names asked for (all of ``known`` for None), in order.

    Raises:
        ValueError: a name not in ``known``, named with the ``kind`` of thing it should be.
    """
    picked = list(known if names is None else names)
    for name in picked:
        if name not in known:
            raise ValueError(f"unknown {kind} {name!r}; expected one of {', '.join(known)}")
    return picked


def prepare(out: Path, provenance: Provenance | None, comm: MPI.Comm = MPI.COMM_WORLD) -> tuple[Path, Provenance]:
    """The output folder ``out``, made on rank 0, and the provenance of what will be written there
    (``provenance``, or this process's now).

    Note:
        Collective.
    """
    out = Path(out)
    if comm.rank == 0:
        out.mkdir(parents=True, exist_ok=True)
    return out, provenance or Provenance.now(comm=comm)


def sweep(cases: Iterable, run: Callable[..., dict], describe: Callable[[dict], str],
          save: Callable[[list[dict]], None], comm: MPI.Comm = MPI.COMM_WORLD, log=print) -> list[dict]:
    """Run ``run(*case)`` for each case; after each, rank 0 logs ``describe(row)`` and saves all
    rows so far (``save``: e.g. rewrite the CSV). Returns the rows.

    Note:
        Collective: every rank runs every case.
    """
    rows: list[dict] = []
    for case in cases:
        rows.append(run(*case))
        if comm.rank == 0:
            log(describe(rows[-1]))
            save(rows)
    return rows


def read_rows(path: Path, failures: str, key: Sequence[str]) -> list[tuple[dict, dict]]:
    """The rows of a study's CSV as text, each with the row of the failures CSV ``failures``
    beside it that has the same ``key`` columns ({} for a run that did not fail, or without
    that file): to merge studies run in parts and write their reports again (a key column
    missing from older files reads as empty)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    failed = {}
    beside = Path(path).with_name(failures)
    if beside.exists():
        with open(beside, newline="") as f:
            failed = {tuple(r.get(c) or "" for c in key): r for r in csv.DictReader(f)}
    return [(r, failed.get(tuple(r.get(c) or "" for c in key), {})) for r in rows]
