"""Hanging block (docs/verification.md) with CPDI1 and CPDI2 domains on 1 and 2 ranks, structured
quadrilaterals and unstructured triangles: the block stretches to over twice its length and
stays continuous, and the parallel run equals the serial one. On triangles the stretched
domains reach cells beyond the ghost layer of the other rank (:mod:`fempm.particles.halo`)."""

import numpy as np
import pytest
from mpi4py import MPI

from fempm.scenes import hanging_block, largest_neighbour_gap


comm = MPI.COMM_WORLD


def history(mesh, c, t_end=0.1, domain="cpdi1"):
    scene = hanging_block(domain=domain, mesh=mesh, t_end=t_end, comm=c)
    solver, p, h = scene.solver(), scene.particles, scene.params["h"]
    gaps, bottom = [], []
    while solver.t < t_end:
        solver.step(dt_max=t_end - solver.t)
        gaps.append(largest_neighbour_gap(p) / h)
        bottom.append(c.allreduce(float(p.x[:, 1].min(initial=np.inf)), op=MPI.MIN))
    return np.array(gaps), np.array(bottom), solver, p


@pytest.mark.skipif(comm.size == 1, reason="compares the ranks with one rank (tests/scenes/test_hanging_block.py: serial)")
@pytest.mark.parametrize("domain", ["cpdi1", "cpdi2"])
@pytest.mark.parametrize("mesh", ["structured", "unstructured"])
@pytest.mark.parallel(only=("structured-cpdi1", "unstructured-cpdi2"))
def test_cpdi_hanging_block_parallel_equals_serial(mesh, domain):
    gaps, bottom, solver, p = history(mesh, comm, domain=domain)
    sgaps, sbottom, _, _ = history(mesh, MPI.COMM_SELF, domain=domain)
    np.testing.assert_allclose(gaps, sgaps, rtol=0, atol=1e-8)
    np.testing.assert_allclose(bottom, sbottom, rtol=0, atol=1e-10)
    assert gaps.max() < 2.0  # measured CPDI1 1.49 / 1.48, CPDI2 1.69 / 1.58 (structured / unstructured)
    assert bottom.min() < -2.4  # stretched to over 2.4 times its length (measured -2.55 at t = 0.09)
    if comm.size > 1:
        assert comm.allreduce(int(len(p) > 0), op=MPI.SUM) == comm.size  # the block spans both ranks
        if mesh == "unstructured":  # corners beyond the ghost layer were evaluated remotely
            assert comm.allreduce(solver.extended_steps, op=MPI.MAX) > 0


@pytest.mark.skipif(comm.size == 1, reason="compares the ranks with one rank")
@pytest.mark.parallel
def test_point_basis_separates_on_two_ranks():
    """Standard MPM on the same block: the lower rows fall away within t = 0.05 (measured
    7.1 cell sizes), on 2 ranks as on one."""
    gaps, _, _, _ = history("structured", comm, t_end=0.05, domain="point")
    sgaps, _, _, _ = history("structured", MPI.COMM_SELF, t_end=0.05, domain="point")
    np.testing.assert_allclose(gaps, sgaps, rtol=0, atol=1e-8)
    assert gaps[-1] > 5.0
