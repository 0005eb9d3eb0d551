"""Two disks: momentum conserved to round-off, rebound, and the same result on 1 and 2 ranks."""

from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from fempm.scene import run
from fempm.scenes import two_disks


comm = MPI.COMM_WORLD


@pytest.mark.parametrize("mesh", ["structured", "unstructured"])
def test_two_disks_conserve_momentum_and_rebound(mesh, tmp_path):
    scene = two_disks(mesh=mesh, t_end=3.0, frames=3)
    out = Path(comm.bcast(str(tmp_path), root=0)) / "out"  # one folder for all ranks
    r = run(scene, out, progress=False)
    h = r["history"]
    p = np.array([[row["momentum_x"], row["momentum_y"]] for row in h])
    assert np.abs(p - p[0]).max() < 1e-13
    ke = np.array([row["kinetic"] for row in h])
    t = np.array([row["t"] for row in h])
    assert ke.min() < 0.1 * ke[0] and 1.5 < t[ke.argmin()] < 2.3  # the collision
    assert ke[-1] > 0.8 * ke[0]  # the rebound
    part = scene.particles
    lower = (part.x.sum(axis=1) < 1.0).astype(float)
    v_low = comm.allreduce((part.mass * lower) @ part.fields["v"]) / comm.allreduce(part.mass @ lower)
    assert v_low[0] < -0.05 and v_low[1] < -0.05  # moving back towards the corner
    assert r["terms_assembled"] == {"internal": r["steps"]}  # no gravity, no traction work


@pytest.mark.parallel
def test_two_disks_parallel_equals_serial():
    serial = run(two_disks(t_end=2.5, comm=MPI.COMM_SELF), None, progress=False)["history"]
    world = run(two_disks(t_end=2.5, comm=comm), None, progress=False)["history"]
    assert len(serial) == len(world)
    for key in ("momentum_x", "momentum_y", "kinetic", "strain", "total"):
        a = np.array([r[key] for r in serial])
        b = np.array([r[key] for r in world])
        assert np.abs(a - b).max() < 1e-10 * max(1.0, np.abs(a).max()), key
