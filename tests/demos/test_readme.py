"""The README's commands work as written on a fresh clone after `make demo`: its Python
examples, and its `python -m fempm run / resume` commands made small (at most 10 cells and
0.2 s of simulated time, the resumes 0.2 s further), in one folder where the demo wrote
output/disks first, serial and under mpiexec as written. Studies and benchmarks (minutes)
are run by their own tests."""

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text()
pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="starts its own processes")


def blocks(kind: str) -> list[str]:
    return re.findall(rf"```{kind}\n(.*?)```", README, flags=re.S)


def commands() -> list[list[str]]:
    """The README's `python -m fempm run|resume` command lines (.venv paths as written)."""
    out = []
    for block in blocks("bash"):
        for line in block.splitlines():
            line = line.split("#")[0].strip()
            if re.match(r"^(\.venv/bin/mpiexec .*)?\.venv/bin/python -m fempm (run|resume)", line) or \
                    re.match(r"^\.venv/bin/mpiexec -n \d+ \.venv/bin/python -m fempm (run|resume)", line):
                out.append(shlex.split(line))
    return out


def small(args: list[str]) -> list[str]:
    """A README command at a small size: --cells at most 10, run --t-end at most 0.2, resume
    --t-end 0.2 later than the run's; the interpreter and mpiexec of this environment."""
    args = [sys.executable if a == ".venv/bin/python" else str(Path(sys.executable).with_name("mpiexec"))
            if a == ".venv/bin/mpiexec" else a for a in args]
    resume = "resume" in args
    for flag, limit in (("--cells", 10), ("--t-end", 0.4 if resume else 0.2)):
        if flag in args:
            k = args.index(flag) + 1
            args[k] = str(min(type(limit)(float(args[k])), limit) if not resume else limit)
        elif flag == "--t-end" and not resume and "--help" not in args:
            args += [flag, str(limit)]
    return args


def test_the_readme_has_the_commands_this_test_runs():
    assert len(blocks("python")) >= 2
    cmds = [" ".join(c) for c in commands()]
    assert any("resume output/disks-restart" in c for c in cmds) and any("mpiexec -n 2" in c for c in cmds)
    assert "import fempm, dolfinx" in README  # fempm before dolfinx: the wheel's MPI first


def test_the_readme_commands_work_as_written_after_make_demo(tmp_path):
    demo = subprocess.run([sys.executable, str(ROOT / "demos" / "two_disks.py"), "--t-end", "0.1", "--no-plot"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert demo.returncode == 0, demo.stderr[-2000:]
    assert (tmp_path / "output" / "disks" / "summary.json").exists()  # what `make demo` leaves
    for k, block in enumerate(blocks("python")):
        script = tmp_path / f"readme_{k}.py"
        script.write_text(block.replace('two_disks(mesh="unstructured", mass="lumped")',
                                        'two_disks(mesh="unstructured", mass="lumped", t_end=0.2)'))
        r = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, (block, r.stderr[-2000:])
    for args in commands():
        r = subprocess.run(small(args), cwd=tmp_path, capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, (" ".join(args), r.stderr[-2000:])
    assert (tmp_path / "output" / "disks-restart" / "checkpoint" / "manifest.json").exists()
