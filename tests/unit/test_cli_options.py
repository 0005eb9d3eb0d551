"""Typed scene options on the command line, and the particle frames' times file."""

import csv
import dataclasses

import pytest
from mpi4py import MPI

from fempm.cli import _scene_options
from fempm.scene import run
from fempm.scenes import vibrating_bar as bar


@pytest.mark.parametrize("value, expected", [("False", False), ("true", True), ("0", False), ("on", True)])
def test_boolean_options_are_converted(value, expected):
    assert _scene_options(bar, ["--lumped-forces", value]) == {"lumped_forces": expected}


@pytest.mark.parametrize("argv, message", [
    (["--lumped-forces", "maybe"], "option --lumped-forces expects true or false, got 'maybe'"),
    (["--cells", "abc"], "option --cells expects an integer, got 'abc'"),
    (["--cells", "2.5"], "option --cells expects an integer, got '2.5'"),
    (["--cfl", "fast"], "option --cfl expects a number, got 'fast'"),
])
def test_bad_option_values_name_the_option(argv, message):
    with pytest.raises(SystemExit, match=message):
        _scene_options(bar, argv)


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="one output folder per rank otherwise")
def test_frame_times_are_plain_numbers(tmp_path):
    scene = bar(cells=8, t_end=0.5, comm=MPI.COMM_SELF)
    gimp = dataclasses.replace(scene.options, domain="gimp")  # the generic step: numpy scalar times
    run(dataclasses.replace(scene, frames=3, options=gimp), tmp_path, progress=False)
    rows = list(csv.reader(open(tmp_path / "particles" / "times.csv")))
    assert len(rows) >= 3
    times = [float(t) for _, t in rows]  # 'np.float64(...)' would not parse
    assert times[0] == 0.0 and times == sorted(times) and times[-1] > 0.4
