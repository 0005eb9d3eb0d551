"""docs/scenes.md runs as written: its Python examples (the beam hit by a box collider on a
tagged gmsh boundary, the plate on the shipped gmsh mesh), in a folder holding the repository's
meshes/, the beam run to 0.03 s; they write what ParaView reads and the summary they print."""

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[2]
GUIDE = (ROOT / "docs" / "scenes.md").read_text()
pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="starts its own processes")


def test_the_guide_examples_run(tmp_path):
    blocks = re.findall(r"```python\n(.*?)```", GUIDE, flags=re.S)
    assert len(blocks) == 2
    (tmp_path / "meshes").symlink_to(ROOT / "meshes")
    for name, block in zip(("beam", "plate"), blocks):
        script = tmp_path / f"{name}.py"
        script.write_text(block.replace("t_end=0.2,", "t_end=0.03,"))
        r = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr[-3000:]
        assert r.stdout.strip().splitlines()[-1].startswith("completed")
        out = tmp_path / "output" / name
        summary = json.loads((out / "summary.json").read_text())
        assert summary["status"] == "completed"
        for series in ("particles.pvd", "grid_velocity.pvd", "energies.csv"):
            assert (out / series).exists()
    beam = json.loads((tmp_path / "output" / "beam" / "summary.json").read_text())
    assert beam["tip_deflection"] < 0.0 and beam["colliders"][0]["impulse"][1] > 0.0  # sagging; the box pushed
