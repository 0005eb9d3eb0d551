"""A disk fired onto a plate at 0.86 times the wave speed (fempm.scenes.disk_impact): with one
grid velocity field the bodies stick and the interface is crushed (the run stops with J <= 0);
with contact the disk stops on the plate's surface and rebounds, no particle column under it
crosses the plate's, no cell holds both bodies at the end, and serial = 2 ranks."""

import json

import numpy as np
import pytest
from mpi4py import MPI

from fempm.scene import run
from fempm.scenes.impact import disk_impact
from fempm.stepping import SimulationError

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD


def _contact_run(c):
    scene = disk_impact(cells=20, frames=0, comm=c)
    summary = run(scene, progress=False)
    p = scene.particles
    ids = np.concatenate(c.allgather(p.ids))
    return summary, np.concatenate(c.allgather(p.x))[np.argsort(ids)]


def test_with_contact_the_disk_rebounds_without_interpenetration():
    summary, x = _contact_run(comm)
    assert summary["status"] == "completed"
    assert summary["penetration"] < -0.2  # in particle spacings: the columns never crossed
    assert summary["rebound"] > 4.0  # m/s, up: it bounced back from 10 m/s down
    assert summary["shared_cells"] == 0
    assert summary["health"]["j_min"] > 0.4
    if comm.size > 1:
        np.testing.assert_allclose(x, _contact_run(MPI.COMM_SELF)[1], rtol=0, atol=1e-10)


def test_with_one_field_the_interface_is_crushed():
    with pytest.raises(SimulationError, match="J <= 0"):
        run(disk_impact(cells=20, frames=0, contact=False), progress=False)


def test_cli(tmp_path):
    from fempm.cli import main

    out = comm.bcast(str(tmp_path), root=0)
    assert main(["run", "impact", "--cells", "10", "--t-end", "0.02", "--out", out + "/run"]) == 0
    summary = json.load(open(out + "/run/summary.json"))
    assert set(summary) >= {"penetration", "rebound", "shared_cells"}
    with pytest.raises(ValueError, match="speed"):
        disk_impact(speed=0.0)
