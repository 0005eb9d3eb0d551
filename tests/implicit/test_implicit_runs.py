"""Implicit runs of scenes: the command line's stepping options, Cook's summary, and a resumed
implicit run against the uninterrupted one."""

import csv
import json

import pytest
from mpi4py import MPI

from fempm.cli import main
from fempm.scenes.cook import displacement_reference

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="command-line output on one rank")

def test_cook_quasi_static_from_the_command_line(tmp_path):
    argv = ["run", "cook", "--out", str(tmp_path), "--h", "4", "--frames", "1", "--integrator", "implicit",
            "--dynamics", "quasi-static", "--steps", "3"]
    assert main(argv) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    ux, uy = summary["corner_displacement"]
    assert summary["status"] == "completed" and summary["steps"] == 3
    # the P1 answer on the scene's mesh (docs/convergence.md: -4.9 % of the converged value at h = 4)
    assert uy / 1e-3 == pytest.approx(displacement_reference(1 / 3, h=4.0)[1], rel=5e-4) and ux < 0.0


@pytest.mark.parametrize("argv, message", [
    (["--integrator", "implicit"], "an implicit run takes fixed steps: give --steps N"),
    (["--integrator", "implicitly", "--steps", "2"], "option --integrator expects one of explicit, implicit"),
    (["--integrator", "implicit", "--dynamics", "static", "--steps", "2"], "option --dynamics expects one of newmark"),
    (["--dynamics", "newmark"], "option --dynamics applies to --integrator implicit"),
    (["--integrator", "implicit", "--steps", "0"], "option --steps expects a positive number of steps, got '0'"),
    (["--integrator", "implicit", "--steps", "2", "--mass", "fmpm2"], "not FMPM"),
])
def test_bad_stepping_options_exit_2_with_one_line(argv, message, capsys, tmp_path):
    code = main(["run", "cook", "--h", "6", "--frames", "0", "--out", str(tmp_path), *argv])
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err


def test_fbar_from_the_command_line(tmp_path):
    argv = ["run", "cook", "--out", str(tmp_path), "--h", "6", "--nu", "0.4999", "--frames", "0", "--t-end", "20",
            "--volumetric", "fbar"]
    assert main(argv) == 0
    assert json.loads((tmp_path / "summary.json").read_text())["status"] == "completed"
    assert main(["run", "cook", "--out", str(tmp_path), "--overwrite", "--volumetric", "bbar"]) == 2


def last_row(folder):
    return list(csv.DictReader(open(folder / "energies.csv")))[-1]


def test_a_resumed_newmark_run_repeats_the_uninterrupted_one(tmp_path):
    common = ["--cells", "8", "--integrator", "implicit", "--dynamics", "newmark"]
    whole, part = tmp_path / "whole", tmp_path / "part"
    assert main(["run", "bar", "--out", str(whole), "--t-end", "8", "--steps", "8", *common]) == 0
    assert main(["run", "bar", "--out", str(part), "--t-end", "4", "--steps", "4", "--checkpoint-every", "2",
                 *common]) == 0
    assert main(["resume", str(part), "--t-end", "8"]) == 0
    a, b = last_row(whole), last_row(part)
    assert a["step"] == b["step"] == "8"
    assert a == b  # the same state, to the digit
