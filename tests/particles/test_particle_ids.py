"""Particle ids are checked unique over all ranks without gathering them: each id goes to the
rank ``id mod size``, which checks its share (the same answer as a gather of every id)."""

import numpy as np
import pytest
from mpi4py import MPI

from fempm.particles.particle_set import repeated_ids

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD


@pytest.mark.parametrize("case", ["unique", "repeated within a rank", "repeated across ranks", "negative", "empty"])
def test_repeated_ids_are_those_a_gather_finds(case):
    rng = np.random.default_rng(comm.rank)
    r = comm.rank
    ids = {"unique": np.arange(50) + 50 * r,
           "repeated within a rank": np.array([3, 3, 9]) + 1000 * r,
           "repeated across ranks": np.concatenate([np.arange(20) + 20 * r, [7, 123456789]]),
           "negative": -np.arange(5) - 5 * r,
           "empty": np.zeros(0, dtype=np.int64)}[case]
    ids = rng.permutation(ids)
    every = np.concatenate(comm.allgather(ids))
    values, counts = np.unique(every, return_counts=True)
    assert repeated_ids(ids, comm) == values[counts > 1][:5].tolist()
