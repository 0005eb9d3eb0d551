r"""The grid solves of the projection, one per mass model: :math:`\sum_j m_{ij} F_j = b_i` on
the dofs the particles support.

* :class:`LumpedSolve`: :math:`F_i = b_i / m_i` with the row sums
  :math:`m_i = \sum_p M_p \langle N_i \rangle_p` (a non-negative basis);
* :class:`FMPMSolve`: k Richardson steps from the lumped solve towards the consistent one
  (:func:`fempm.transfer.fmpm.fmpm_solve`), matrix-free;
* :class:`MatrixSolve`: the consistent matrix
  :math:`m_{ij} = \sum_p M_p \langle N_i N_j \rangle_p` assembled and solved with a PETSc KSP,
  one system per velocity component a slip condition constrains.

A mass model (:mod:`fempm.transfer.mass_models`) makes its solve
(:meth:`fempm.transfer.mass_models.MassModel.grid_solve`); :class:`fempm.transfer.Projector`
asks it which dofs the particles support (:meth:`GridSolve.support_measure`), sets it up on
them (:meth:`GridSolve.set_up`) and calls :meth:`GridSolve.solve`. A new mass model adds a
subclass of :class:`GridSolve` here and a :class:`MassModel` that makes it; the projector does
not change.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from fempm import petsc as fpetsc
from fempm.transfer.basis import ParticleBasis
from fempm.transfer.fmpm import fmpm_solve
from fempm.transfer.mapping import cell_blocks, consistent_mass_matrix, p2g
from fempm.transfer.mass_span import check_nonsingular, mass_ratio_estimate, mass_ratio_ksp, mass_ratio_rhs

__all__ = ["FMPMSolve", "GridSolve", "LumpedSolve", "MatrixSolve"]


class GridSolve:
    """The solve of one mass model on the particles' weights.

    Args:
        basis: the basis at the particles.
        weights: a weight per particle (mass, volume, or one body's masses).
        label: the mass model's name in messages.

    Attributes:
        row_mass: the row sums of the mass on the active owned dofs (0 elsewhere), after
            :meth:`set_up`.
        iterations: the KSP iterations of the last :meth:`solve`, per component (a matrix only).
    """

    def __init__(self, basis: ParticleBasis, weights: npt.NDArray, label: str):
        self.basis, self.weights, self.label = basis, weights, label
        self.num_owned = basis.index_map.size_local
        self.row_mass = np.zeros(0)
        self.iterations: list[int] = []

    def support_measure(self, lumped: Callable[[], npt.NDArray]) -> npt.NDArray:
        """How strongly the particles support each owned + ghost dof (the dofs above a fraction
        of the largest are solved for); ``lumped()`` gives the lumped masses."""
        raise NotImplementedError

    def set_up(self, active: npt.NDArray[np.bool_], lump: npt.NDArray[np.bool_] | None,
               exclude_components: Sequence[npt.NDArray[np.int32]], lumped: Callable[[], npt.NDArray],
               petsc_options_prefix: str, petsc_options: dict[str, Any] | None) -> None:
        """Prepare the solve on the ``active`` dofs (owned + ghost mask); ``lump``: the dofs whose
        rows and columns are lumped; ``exclude_components[c]``: dofs whose component c is held
        at 0. Collective."""
        raise NotImplementedError

    def solve(self, b: npt.NDArray, guess: npt.NDArray | None,
              ghosted: Callable[[npt.NDArray], npt.NDArray], start: npt.NDArray | None = None) -> npt.NDArray:
        """F on the owned dofs, (owned dofs, k), for the right-hand sides ``b`` (owned + ghost
        dofs, k); 0 on inactive dofs. ``guess`` may warm-start an iterative solve; ``ghosted``
        updates ghosts of owned values (FMPM needs them between its steps); ``start`` (like
        ``b``): a term of the first, lumped solve alone, :math:`m^{-1}(b + s)`, which the
        lumped mass solves with ``b``, FMPM corrects with the residual of ``b`` and the exact
        projection leaves out (the affine part of APIC/TPIC: :mod:`fempm.transfer.transfers`).
        Collective."""
        raise NotImplementedError

    def mass_ratio_min(self, iterations: int) -> float:
        r"""An estimate of :math:`\lambda_{min}(M_L^{-1} m)` (1 for a lumped mass). Collective."""
        return 1.0


def negative_basis_message(label: str, degree: int) -> str:
    """The error of a lumped (or FMPM) mass on a Lagrange basis that takes negative values."""
    return (f"{label} mass needs a non-negative basis (degree 1 or Bernstein); this Lagrange space of degree "
            f"{degree} has lumped vertex masses that can be zero or negative: use mass='consistent' or a "
            "Bernstein variant")


class LumpedSolve(GridSolve):
    """:math:`F_i = b_i / m_i` on the active dofs, component by component where slip holds one."""

    def support_measure(self, lumped):
        if not self.basis.nonnegative:
            raise ValueError(negative_basis_message(self.label, self.basis.element.degree))
        return lumped()

    def set_up(self, active, lump, exclude_components, lumped, petsc_options_prefix, petsc_options):
        n = self.num_owned
        self.active, self.lump = active[:n], None if lump is None else lump[:n]
        self.lumped = lumped()
        self.row_mass = np.where(active, self.lumped, 0.0)[:n]
        self.exclude_components = list(exclude_components)

    def free(self, k: int) -> npt.NDArray[np.bool_]:
        """The (owned dofs, k) mask of the values solved for."""
        n = self.num_owned
        free = np.repeat(self.active[:, None], k, axis=1)
        for c, dofs in enumerate(self.exclude_components[:k]):
            free[dofs[dofs < n], c] = False
        return free

    def solve(self, b, guess, ghosted, start=None):
        n = self.num_owned
        free = self.free(b.shape[1])
        F = np.zeros((n, b.shape[1]))
        rhs = b[:n] if start is None else b[:n] + start[:n]
        F[free] = (rhs / np.where(self.active, self.lumped[:n], 1.0)[:, None])[free]
        return F


class FMPMSolve(LumpedSolve):
    """FMPM(k): ``order`` Richardson steps from the lumped solve (lumped rows keep it)."""

    def __init__(self, basis: ParticleBasis, weights: npt.NDArray, label: str, order: int):
        super().__init__(basis, weights, label)
        self.order = order

    def solve(self, b, guess, ghosted, start=None):
        return fmpm_solve(self.basis, self.weights, self.lumped, b, self.free(b.shape[1]), self.order, ghosted,
                          lump=self.lump, start=start)


class MatrixSolve(GridSolve):
    """The consistent matrix on the active dofs and its KSP (options prefix as given).

    Args:
        particles: the particles (their communicator; the count for the singularity test).
        weight: "mass" or "volume" (the matrix's weights, see :func:`consistent_mass_matrix`).
        given_weights: whether the weights were given per particle (some may be 0).
    """

    def __init__(self, basis: ParticleBasis, weights: npt.NDArray, label: str, particles, weight: str,
                 given_weights: bool):
        super().__init__(basis, weights, label)
        self.particles, self.weight, self.given_weights = particles, weight, given_weights

    def support_measure(self, lumped):
        return p2g(self.basis, self.weights, values=self.basis.values**2)[:, 0]

    def set_up(self, active, lump, exclude_components, lumped, petsc_options_prefix, petsc_options):
        particles, imap, n = self.particles, self.basis.index_map, self.num_owned
        comm = particles.comm
        blocks = None
        if self.basis.cells is not None:  # point particles: the cell blocks, once for the test and the matrix
            blocks = cell_blocks(self.basis, self.weights)
        weighted = comm.allreduce(int(np.count_nonzero(self.weights))) if self.given_weights else particles.num_global
        check_nonsingular(imap, weighted, active, lump, blocks)
        A = consistent_mass_matrix(self.basis, particles, lump, self.weight, blocks, self.weights)
        self.active = active[:n]
        self.matrix = A.createSubMatrix(*[fpetsc.owned_index_set(imap, self.active)] * 2)
        ksp = fpetsc.create_ksp(comm, petsc_options_prefix, petsc_options)
        ksp.setOperators(self.matrix)
        self.systems = [(self.active, ksp, *self.matrix.createVecs())]
        for dofs in exclude_components:  # a system per constrained component
            act = active.copy()
            act[np.asarray(dofs, dtype=np.int32)] = False
            self.systems.append(self.systems[0])
            if comm.allreduce(int(np.count_nonzero(act != active))):
                M = A.createSubMatrix(*[fpetsc.owned_index_set(imap, act[:n])] * 2)
                sub = fpetsc.create_ksp(comm, petsc_options_prefix, petsc_options)
                sub.setOperators(M)
                self.systems[-1] = (act[:n], sub, *M.createVecs())
        A.destroy()
        ones, rows = self.matrix.createVecs()
        ones.set(1.0)
        self.matrix.mult(ones, rows)
        self.row_mass = np.zeros(n)
        self.row_mass[self.active] = rows.array

    def solve(self, b, guess, ghosted, start=None):  # the exact projection: no lumped first solve
        n, k = self.num_owned, b.shape[1]
        F = np.zeros((n, k))
        self.iterations = []
        for c in range(k):
            act, ksp, x, rhs = self.systems[c + 1] if c + 1 < len(self.systems) else self.systems[0]
            rhs.array[:] = b[:n][act, c]
            if guess is None:
                x.set(0.0)
            else:
                x.array[:] = guess[:n][act, c]
            reason = fpetsc.solve_from(ksp, rhs, x, guess is not None)
            if reason < 0:
                raise RuntimeError(
                    f"consistent projection: KSP did not converge ({fpetsc.converged_reason_name(reason)}, "
                    f"{ksp.getIterationNumber()} iterations); the particle mass matrix may be "
                    "singular: too few particles per cell for this space?"
                )
            self.iterations.append(ksp.getIterationNumber())
            F[act, c] = x.array
        return F

    def mass_ratio_min(self, iterations):
        ksp = mass_ratio_ksp(self.particles.comm, iterations, rowsum=self.basis.nonnegative)
        x, b = self.matrix.createVecs()
        b.array[:] = mass_ratio_rhs(self.basis.V, self.active) * np.abs(self.row_mass[self.active])
        ratio = mass_ratio_estimate(ksp, self.matrix, b, x)
        for obj in (ksp, x, b):
            obj.destroy()
        return ratio
