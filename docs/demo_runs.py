"""The demos as pages of the site, executed when it is built (as DOLFINx renders its demos).

Each demo's page (``docs/demos/<name>.md``, generated, not kept in git) is its module docstring
(markdown), its code, and a run of it: the command (the demo's ``DOCS_RUN`` arguments, a small
size), what it printed and the figures it wrote, run by the build with the interpreter that runs
Sphinx. A run is kept under ``docs/_build/demo-runs/<name>`` with the hash of the demo's source,
its arguments and the package's source, and made again only when one of them changes.

``FEMPM_DOCS_DEMOS=code`` (the test run's build: the tests run every demo themselves) writes the
pages without the runs. A demo that fails fails the build, naming it, with its output.
"""

from __future__ import annotations

import ast
import hashlib
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DEMOS = ROOT / "demos"
PAGES = HERE / "demos"
RUNS = HERE / "_build" / "demo-runs"
#: the lines of a run's output a page shows (the last ones)
MAX_LINES = 60
#: the longest a demo's run may take (s)
TIMEOUT = 1200


class DemoRunError(RuntimeError):
    """A demo's run failed while the site was built."""


def docs_run(source: str) -> list[str] | None:
    """The demo's ``DOCS_RUN`` arguments (a literal list of strings at module level), or None."""
    for node in ast.parse(source).body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "DOCS_RUN" for t in node.targets):
            value = ast.literal_eval(node.value)
            if not (isinstance(value, list) and all(isinstance(a, str) for a in value)):
                raise DemoRunError(f"DOCS_RUN must be a list of strings, got {value!r}")
            return value
    return None


def package_hash() -> str:
    """A hash of the package's source (a run is made again when the library changes)."""
    h = hashlib.sha256()
    for path in sorted((ROOT / "fempm").rglob("*.py")):
        h.update(path.read_bytes())
    return h.hexdigest()


def run_demo(path: Path, args: list[str], out: Path, library: str) -> dict:
    """Run ``path`` with ``args`` into ``out`` (unless the kept run has the same hash): the
    command, what it printed, its figures (the ``*.png`` it wrote at the top of ``out``) and the
    run's time and date."""
    key = hashlib.sha256(path.read_bytes() + "\0".join(args).encode() + library.encode()).hexdigest()
    stamp = out / "run.key"
    if not (stamp.exists() and stamp.read_text().splitlines()[0] == key):
        shutil.rmtree(out, ignore_errors=True)
        out.mkdir(parents=True)
        start = time.perf_counter()
        env = {**os.environ, "MPLBACKEND": "Agg", "PYVISTA_OFF_SCREEN": "true", "OMP_NUM_THREADS": "1"}
        proc = subprocess.run([sys.executable, str(path), *args, "--out", str(out / "files")], cwd=ROOT, env=env,
                              capture_output=True, text=True, timeout=TIMEOUT)
        seconds = time.perf_counter() - start
        if proc.returncode != 0:
            raise DemoRunError(f"demos/{path.name} {' '.join(args)} exited with {proc.returncode}:\n"
                               f"{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
        (out / "stdout.txt").write_text(proc.stdout)
        stamp.write_text(f"{key}\n{seconds:.1f}\n{time.strftime('%Y-%m-%d')}\n")
    _, seconds, date = stamp.read_text().splitlines()[:3]
    figures = sorted((out / "files").glob("*.png"))
    return {"stdout": (out / "stdout.txt").read_text(), "figures": figures, "seconds": float(seconds), "date": date}


def run_section(path: Path, args: list[str], run: dict, pages: Path = PAGES) -> str:
    """The page's section of a run: the command, its output (the last lines), its figures
    (copied next to the page, into ``pages/<name>``)."""
    lines = run["stdout"].rstrip("\n").splitlines()
    shown = lines[-MAX_LINES:]
    if len(lines) > len(shown):
        shown = [f"... ({len(lines) - len(shown)} lines before)", *shown]
    command = " ".join([".venv/bin/python", f"demos/{path.name}", *(f'"{a}"' if " " in a else a for a in args)])
    text = (f"\n## A run\n\nMade when this site was built ({run['date']}, {run['seconds']:.0f} s on the build "
            f"machine), at a small size:\n\n```text\n{command}\n```\n\nIt printed:\n\n```text\n"
            + "\n".join(shown) + "\n```\n")
    folder = pages / path.stem
    shutil.rmtree(folder, ignore_errors=True)
    if run["figures"]:
        folder.mkdir(parents=True)
        text += "\nIts figures:\n"
        for fig in run["figures"]:
            shutil.copy(fig, folder / fig.name)
            text += f"\n![{fig.stem}]({path.stem}/{fig.name})\n"
    return text


def demo_page(path: Path, run: str = "") -> str:
    """A demo as a page: its module docstring (markdown), then its code, then ``run`` (the
    section of :func:`run_section`, or nothing)."""
    source = path.read_text()
    tree = ast.parse(source)
    doc = ast.get_docstring(tree) or f"# {path.stem}"
    body = source.splitlines()[tree.body[0].end_lineno:] if ast.get_docstring(tree) else source.splitlines()
    code = "\n".join(body).strip("\n")
    return (f"{doc}\n\n## The script\n\n`demos/{path.name}`; run it with `.venv/bin/python demos/{path.name} --help` "
            f"for its options.\n\n```python\n{code}\n```\n{run}")


def write_demo_pages(demos: Path = DEMOS, pages: Path = PAGES, runs: Path = RUNS,
                     execute: bool | None = None) -> list[Path]:
    """``pages/<name>.md`` for every ``demos/<name>.py``, each with a run of its ``DOCS_RUN``
    unless ``execute`` is False (None: unless ``FEMPM_DOCS_DEMOS=code``). Returns the pages.

    Raises:
        DemoRunError: A demo without ``DOCS_RUN`` (with ``execute``), or one whose run failed.
    """
    if execute is None:
        execute = os.environ.get("FEMPM_DOCS_DEMOS", "run") != "code"
    pages.mkdir(parents=True, exist_ok=True)
    library = package_hash() if execute else ""
    written = []
    for path in sorted(demos.glob("*.py")):
        section = ""
        if execute:
            args = docs_run(path.read_text())
            if args is None:
                raise DemoRunError(f"demos/{path.name} has no DOCS_RUN: the arguments of the run its page shows")
            section = run_section(path, args, run_demo(path, args, runs / path.stem, library), pages)
        page = pages / f"{path.stem}.md"
        text = demo_page(path, section)
        if not page.exists() or page.read_text() != text:
            page.write_text(text)
        written.append(page)
    return written
