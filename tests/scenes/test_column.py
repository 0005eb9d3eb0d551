"""The granular column collapse scene (fempm.scenes.column) at a small size: a column of
aspect ratio 1 collapses to a deposit at rest, with its runout and final height in the band of
the fine runs and of the experiments (docs: the study at four aspect ratios)."""

import json
from pathlib import Path

import pytest
from mpi4py import MPI

from fempm.cli import main
from fempm.scene import run
from fempm.scenes import column_collapse


comm = MPI.COMM_WORLD


def test_a_column_collapses_to_a_deposit_at_rest():
    summary = run(column_collapse(aspect=1.0, cells=6), progress=False)
    assert summary["status"] == "completed"
    assert summary["kinetic_fraction"] < 1e-3  # at rest: kinetic energy / potential energy released
    assert 0.5 < summary["runout"] < 1.3  # (L_inf - L0) / L0; 0.86 with 8 cells across
    assert 0.85 < summary["final_height"] <= 1.0 + 1e-9  # H_inf / L0: the top barely moves at a = 1
    assert summary["health"]["j_max"] < 2.0


@pytest.mark.skipif(comm.size > 1, reason="one output folder")
@pytest.mark.parallel
def test_the_command_line_writes_runout_and_final_height(tmp_path):
    assert main(["run", "column", "--aspect", "0.5", "--cells", "4", "--out", str(tmp_path)]) == 0
    summary = json.loads(Path(tmp_path / "summary.json").read_text())
    assert summary["params"]["aspect"] == 0.5 and 0.0 < summary["runout"] < 1.0
    assert summary["final_height"] == pytest.approx(0.5, abs=0.05)  # a short column keeps its top


def test_published_runout_laws():
    """The experimental laws of fempm.scenes.column.RUNOUT_LAWS: one branch inside a law's
    range, both between them."""
    from fempm.scenes.column import published_runout

    lube, laj = "Lube et al. 2005", "Lajeunesse et al. 2005"
    assert published_runout(1.0) == {lube: (1.2, 1.2), laj: (1.8, 1.8)}
    at2 = published_runout(2.0)
    assert at2[lube] == pytest.approx((2.4, 1.9 * 2 ** (2 / 3)), rel=1e-14)
    assert at2[laj] == pytest.approx((3.6, 3.6))
    assert published_runout(4.0)[lube] == pytest.approx((1.9 * 4 ** (2 / 3),) * 2, rel=1e-14)
    assert published_runout(4.0)[laj] == pytest.approx((2.3 * 4 ** (2 / 3),) * 2, rel=1e-14)
