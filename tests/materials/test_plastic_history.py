"""The laws' internal variables kept by the solver: allocated in the particle fields, updated
by the law, moved with the particles between ranks (serial = 2 ranks to 1e-10 on a plastic
scene), in checkpoints (a resumed plastic run is bit for bit the uninterrupted one) and in the
particle frames."""

import dataclasses
import os
import signal
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from fempm.io.checkpoint import RunInterrupted
from fempm.materials import DruckerPrager, VonMises
from fempm.scene import run
from fempm.scenes import two_disks

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD
T_END = 1.2  # the disks meet near t = 0.8


def _plastic_disks(c, law):
    scene = two_disks(cells=12, ppc=4, t_end=T_END, frames=2, comm=c)
    return dataclasses.replace(scene, materials=[law])


LAWS = [VonMises(1000.0, 0.3, yield_stress=2.0, hardening=5.0),
        DruckerPrager(1000.0, 0.3, friction_angle=30.0, dilation_angle=5.0, cohesion=1.5)]


def _by_id(particles, names):
    ids = np.concatenate(particles.comm.allgather(particles.ids))
    order = np.argsort(ids)
    return {k: np.concatenate(particles.comm.allgather(particles.fields[k] if k != "x" else particles.x))[order]
            for k in names}


@pytest.mark.parametrize("law", LAWS, ids=["von Mises", "Drucker-Prager"])
def test_internal_variables_serial_equals_two_ranks(law):
    names = ("x", "v", "sigma", "eps_p", "sigma_zz")
    here = _by_id(run(_plastic_disks(comm, law), progress=False)["solver"].particles, names)
    assert here["eps_p"].max() > 1e-3 and np.count_nonzero(here["eps_p"]) > 20  # the collision yields
    assert np.abs(here["sigma_zz"]).max() > 0
    serial = _by_id(run(_plastic_disks(MPI.COMM_SELF, law), progress=False)["solver"].particles, names)
    for k in names:
        scale = max(np.abs(serial[k]).max(), 1e-300)
        assert np.abs(here[k] - serial[k]).max() <= 1e-10 * scale, k


def test_a_resumed_plastic_run_is_bit_identical(tmp_path):
    out = Path(comm.bcast(str(tmp_path) if comm.rank == 0 else None))
    law = LAWS[0]
    whole = run(_plastic_disks(comm, law), out / "whole", progress=False)

    def interrupt(solver):
        if solver.t >= 0.9 and not interrupt.sent:
            interrupt.sent = True
            os.kill(os.getpid(), signal.SIGINT)

    interrupt.sent = False
    with pytest.raises(RunInterrupted):
        run(_plastic_disks(comm, law), out / "parts", progress=False, callback=interrupt)
    resumed = run(_plastic_disks(comm, law), out / "parts", progress=False, resume=True)
    a = _by_id(whole["solver"].particles, ("x", "eps_p", "sigma_zz"))
    b = _by_id(resumed["solver"].particles, ("x", "eps_p", "sigma_zz"))
    assert all(np.array_equal(a[k], b[k]) for k in a) and a["eps_p"].max() > 1e-3
    if comm.rank == 0:
        import pyvista as pv

        frame = pv.read(sorted((out / "parts" / "particles").glob("*.vtkhdf"))[-1])
        assert np.array_equal(np.sort(frame.point_data["eps_p"]), np.sort(a["eps_p"]))
