"""The implicit tangent's sparsity kept from step to step: the matrix of the particles' blocks
is laid out once (PETSc's COO preallocation, a quarter of a step's time on Cook's membrane) and
refilled while every particle keeps the dofs it had (its cell), on every rank."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fempm import petsc as fpetsc

__all__ = ["KeptPattern"]


class KeptPattern:
    """The particles' block matrix of the last step, and the dofs it was laid out for."""

    def __init__(self) -> None:
        self.matrix: PETSc.Mat | None = None
        self.dofs: np.ndarray | None = None
        self.index_map = None  # held: the matrix lives on its communicator
        self.layouts = 0  # how many times the pattern was laid out (tests, benchmarks)

    def matrix_for(self, op, index_map, d: int) -> PETSc.Mat:
        """The matrix for the particles of ``op`` (an
        :class:`~fempm.implicit.operator.IncrementOperator`) on ``index_map``: the kept one if
        the index map is the same object (the space's own; particle domains that reach remote
        cells extend it anew every step) and no particle on any rank has other dofs than when it
        was laid out, else a new one (collective)."""
        dofs = op.basis.dofs
        same = (self.matrix is not None and index_map is self.index_map and self.dofs.shape == dofs.shape
                and np.array_equal(self.dofs, dofs))
        if index_map.comm.allreduce(same, op=MPI.LAND):
            return self.matrix
        self.release()
        rows, cols = op.pattern()
        self.matrix = fpetsc.coo_pattern(index_map, rows, cols, bs=d)
        self.dofs, self.index_map = dofs.copy(), index_map
        self.layouts += 1
        return self.matrix

    def release(self) -> None:
        """Free the matrix (local)."""
        if self.matrix is not None:
            self.matrix.destroy()
        self.matrix, self.dofs, self.index_map = None, None, None
