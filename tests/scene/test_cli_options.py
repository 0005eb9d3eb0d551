"""Typed scene options on the command line, and the particle frames' times file."""

import csv
import dataclasses

import numpy as np
import pytest
from mpi4py import MPI

from fempm.run_options import scene_options as _scene_options
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


def test_optional_options_take_their_annotated_type():
    """``ppc: int | None``, ``gap: float | None``, ``t_end: float | None`` of the incline."""
    from fempm.scenes import incline

    opts = _scene_options(incline, ["--ppc", "9", "--gap", "0.7", "--t-end", "1"])
    assert opts == {"ppc": 9, "gap": 0.7, "t_end": 1.0} and type(opts["ppc"]) is int
    with pytest.raises(SystemExit, match="option --ppc expects an integer, got '2.5'"):
        _scene_options(incline, ["--ppc", "2.5"])


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="one output folder per rank otherwise")
def test_frame_times_are_plain_numbers(tmp_path):
    scene = bar(cells=8, t_end=0.5, comm=MPI.COMM_SELF)
    run(dataclasses.replace(scene, frames=3, dt=np.float64(0.01)), tmp_path, progress=False)  # numpy scalar times
    rows = list(csv.reader(open(tmp_path / "particles" / "times.csv")))
    assert len(rows) >= 3
    times = [float(t) for _, t in rows]  # 'np.float64(...)' would not parse
    assert times[0] == 0.0 and times == sorted(times) and times[-1] > 0.4


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="command-line output on one rank")
def test_version_and_the_list_of_scenes(capsys):
    from fempm import __version__
    from fempm.cli import main
    from fempm.scenes import SCENES

    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.strip() == f"fempm {__version__}"
    assert main(["run", "--help"]) == 0
    lines = capsys.readouterr().out.splitlines()
    for name in SCENES:  # one line each, with its description
        (line,) = [x for x in lines if x.split()[:1] == [name]]
        assert len(line.split()) > 4


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="command-line output on one rank")
@pytest.mark.parametrize("scene", ["bar", "disks", "cantilever", "dam", "block", "cook", "column", "incline", "impact",
                                   "compaction", "wave", "footing", "silo", "bowl"])
def test_every_scene_option_has_a_one_line_description_without_markup(scene, capsys):
    """From the scene's own Args: section or, for the options every scene passes on, from
    StepOptions' and Scene's; every scene takes --mass; the health limits are described too."""
    import inspect

    from fempm.cli import main
    from fempm.scenes import SCENES

    assert "mass" in inspect.signature(SCENES[scene]).parameters
    assert main(["run", scene, "--help"]) == 0
    out = capsys.readouterr().out
    options = [x for x in out.splitlines() if x.startswith("  --")]
    names = [k for k in inspect.signature(SCENES[scene]).parameters if k != "comm"]
    assert len(options) == len(names) + 4  # and the four health limits
    for line in options:
        flag, default, *words = line.split()
        assert len(words) >= 2, line  # a description
        assert " ".join(words).endswith(".") or " ".join(words).endswith(")"), line
        assert ":math:" not in line and ":class:" not in line and "``" not in line, line
    for line in options:  # None is explained where it is a default
        if line.split()[1] == "None":
            assert "None" in " ".join(line.split()[2:]), line


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="command-line output on one rank")
@pytest.mark.parametrize("argv, message", [
    (["run"], "fempm run: give a scene"),
    (["run", "nosuch"], "unknown scene 'nosuch'; scenes: bar, disks"),
    (["run", "bar", "--bogus", "1"], "unknown option --bogus"),
    (["run", "bar", "--cells", "abc"], "option --cells expects an integer, got 'abc'"),
    (["run", "bar", "--cells", "0"], "cells"),
    (["run", "bar", "--t-end", "-1"], "t_end"),
    (["run", "bar", "--cfl", "-0.5"], "cfl"),
    (["run", "bar", "--scheme", "XYZ"], "scheme"),
    (["run", "bar", "--j-min", "x"], "option --j-min expects a number"),
    (["run", "bar", "--t_end_x", "1"], "options: --E, --L, --cells, --cfl, --dim, --flip, --lumped-forces"),
    (["run", "cantilever", "--g", "nan"], "option --g expects a finite number, got 'nan'"),
    (["run", "cook", "--variant", "foo"], "unknown option variant='foo'"),
    (["run", "cantilever", "--degree", "2"], "mass='lumped' needs a non-negative basis"),
    (["run", "cantilever", "--degree", "2", "--mass", "consistent", "--ppc", "4"],
     "ppc=4 particles per cell cannot determine the consistent mass of degree 2"),
    (["run", "cook", "--spacing", "-1"], "spacing=-1.0 must be a positive length"),
    (["run", "disks", "--friction", "0.5"], "friction=0.5 needs contact=True"),
    (["run", "impact", "--contact", "no", "--friction", "0.5"], "friction=0.5 needs contact=True"),
    (["run", "disks", "--radius", "0.9"], "radius=0.9 must lie in (0, 0.2]"),
    (["run", "dam", "--ppc", "2"], "ppc=2 particles per cell must be a square"),
])
def test_usage_errors_exit_2_with_one_line(argv, message, capsys):
    from fempm.cli import main

    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="command-line output on one rank")
def test_an_unwritable_output_folder_is_a_usage_error(tmp_path, capsys):
    from fempm.cli import main

    blocker = tmp_path / "f"
    blocker.write_text("a file")
    assert main(["run", "bar", "--cells", "8", "--t-end", "0.1", "--out", str(blocker / "out")]) == 2
    err = capsys.readouterr().err
    assert f"cannot write the output folder '{blocker / 'out'}'" in err and "Not a directory" in err


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="command-line output on one rank")
def test_an_earlier_run_in_the_output_folder_needs_overwrite(tmp_path, capsys):
    from fempm.cli import main

    argv = ["run", "bar", "--cells", "8", "--t-end", "0.5", "--out", str(tmp_path)]
    assert main(argv) == 0
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "holds the outputs of an earlier run" in err and "--overwrite" in err and len(err.strip().splitlines()) == 1
    (tmp_path / "notes.txt").write_text("mine")
    assert main(argv + ["--overwrite"]) == 0
    assert (tmp_path / "notes.txt").read_text() == "mine"  # only the run's own outputs are replaced


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="command-line output on one rank")
def test_a_particle_leaving_the_mesh_exits_3_with_a_summary(tmp_path, capsys):
    """The disks collide, bounce apart and leave the unit square (32 cells, to t = 6): exit 3,
    one message naming the particles outside the mesh, summary.json with status "aborted"."""
    import json

    from fempm.cli import main

    assert main(["run", "disks", "--cells", "32", "--t-end", "6", "--frames", "2", "--out", str(tmp_path)]) == 3
    err = capsys.readouterr().err
    assert "aborted" in err and "lie outside the mesh" in err and "Traceback" not in err
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "aborted" and "outside the mesh" in summary["health"]["error"]


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="command-line output on one rank")
def test_frames_above_2_gb_need_force(tmp_path, capsys):
    """The column at aspect 50 on 8 cells builds a 512,000-cell mesh: 3.3 GB of frames. The run
    stops before it writes anything, saying so, unless --force or fewer --frames."""
    from fempm.cli import main

    argv = ["run", "column", "--aspect", "50", "--cells", "8", "--out", str(tmp_path / "c")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "would write about 3.3 GB of frames (21 frames" in err and "--force" in err
    assert not (tmp_path / "c" / "energies.csv").exists()
    from fempm.io import check_output_size
    from fempm.scenes import column_collapse

    scene = column_collapse(aspect=50.0, cells=8, frames=5)
    assert check_output_size(scene.particles, scene.space(), scene.outputs, scene.frames) < 2e9
