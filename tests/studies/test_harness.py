"""The studies' harness (fempm.studies.harness): the record of what made an output, the names
asked for, and the sweep that saves after every run; and the CLI's ``study all``."""

import json
import re
import subprocess
from pathlib import Path

import pytest
from mpi4py import MPI

from fempm.cli import main
from fempm.studies import particle_basis
from fempm.studies.harness import REPOSITORY, Provenance, _command, chosen, sweep


def test_provenance_names_the_commit_command_and_date(tmp_path):
    prov = Provenance.now(command="python -m fempm study all", comm=MPI.COMM_SELF)
    head = subprocess.run(["git", "-C", str(REPOSITORY), "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True).stdout.strip()
    assert prov.commit.removesuffix("-dirty") == (head or "unknown")
    assert re.fullmatch(r"\d{4}-\d\d-\d\d \d\d:\d\d UTC", prov.date)
    assert prov.line() == f"Made by `python -m fempm study all` at commit {prov.commit} on {prov.date}."
    written = json.loads(prov.write(tmp_path).read_text())
    assert written == {"commit": prov.commit, "command": "python -m fempm study all", "date": prov.date, "ranks": 1}


def test_the_command_reads_as_typed():
    assert _command(["/x/fempm/__main__.py", "study", "all", "--out", "a b"]) == ".venv/bin/python -m fempm study all --out 'a b'"
    assert _command(["benchmarks/bench_step.py", "--cells", "80"]) == ".venv/bin/python benchmarks/bench_step.py --cells 80"


def test_chosen_keeps_the_order_and_names_an_unknown_name():
    assert chosen(None, ["a", "b"], "case") == ["a", "b"]
    assert chosen(["b", "a"], ["a", "b"], "case") == ["b", "a"]
    with pytest.raises(ValueError, match="unknown problem 'c'; expected one of a, b"):
        chosen(["a", "c"], ["a", "b"], "problem")


def test_sweep_saves_every_row_as_it_comes():
    saved, logged = [], []
    rows = sweep([(1,), (2,), (3,)], lambda k: {"k": k, "square": k * k}, lambda r: f"k={r['k']}",
                 lambda rows: saved.append([r["k"] for r in rows]), MPI.COMM_SELF, logged.append)
    assert [r["square"] for r in rows] == [1, 4, 9]
    assert saved == [[1], [1, 2], [1, 2, 3]] and logged == ["k=1", "k=2", "k=3"]


def test_sweep_keeps_what_ran_before_a_failure():
    saved = []

    def run(k):
        if k == 2:
            raise RuntimeError("run 2 failed")
        return {"k": k}

    with pytest.raises(RuntimeError, match="run 2 failed"):
        sweep([(1,), (2,), (3,)], run, str, lambda rows: saved.append(len(rows)), MPI.COMM_SELF, lambda *a: None)
    assert saved == [1]


@pytest.mark.parametrize("option", [["--problems", "vibrating_bar"], ["--cases", "x"], ["--full"], ["--sizes", "8"]])
def test_study_all_takes_no_options_but_the_folder(option, capsys):
    with pytest.raises(SystemExit) as stop:
        main(["study", "all", *option])
    assert stop.value.code == 2
    assert f"it takes --out only, not {option[0]}" in capsys.readouterr().err


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="a study on one rank")
def test_a_study_writes_its_provenance_beside_its_outputs(tmp_path):
    prov = Provenance("abc1234", "python -m fempm study particle-basis", "2026-12-03 10:00 UTC")
    particle_basis.run(tmp_path, figures=False, provenance=prov)
    assert json.loads((tmp_path / "provenance.json").read_text())["commit"] == "abc1234"
    assert (tmp_path / "properties.md").read_text().splitlines()[2] == prov.line()
    assert Path(tmp_path / "properties.csv").exists()
