r"""Consistent mass systems kept for a run: sparsity fixed, values set each step, KSPs kept.

The compiled consistent step (:mod:`fempm.stepping.consistent`) solves
:math:`\sum_j m_{ij} u_j = b_i` with :math:`m_{ij} = \sum_p M_p N_i(x_p) N_j(x_p)` every step,
twice (velocity and acceleration) or three times (MUSL). What :class:`fempm.transfer.Projector`
builds for one use is kept here:

- the *sparsity*: the cells holding particles plus one layer of cells around them (those that
  share a dof), numbered on a sub index map of their dofs (:func:`create_sub_index_map`), so
  vectors and matrix rows cover the particles' region, not the whole mesh; it is rebuilt only
  when a particle enters a cell outside it (with particle domains, or reaches pairs of dofs
  beyond its entries: :mod:`fempm.stepping.mass_sparsity`);
- the *matrices*: one per set of constrained dofs (a velocity component held at 0 on slip walls
  normal to its axis is solved on its own dofs, the constrained fit), their values written with
  ``setValuesCOO`` from the per-cell blocks (:func:`fempm.kernels.consistent.coo_values`): dofs
  not solved for get identity rows and a zero right-hand side, which solves them to 0 exactly as
  removing them would;
- the *KSPs* (the options prefix of the step), warm-started from the last solution;
- the *singularity tests* (:func:`fempm.transfer.mass_span.check_nonsingular`) run when the occupied
  cells, the supported dofs or the lumped dofs change, not every step;
- the *checkpoint state* (:meth:`ConsistentSystems.state`, :meth:`ConsistentSystems.restore`):
  the sparsity's cells and the values each preconditioner was set up from, so that a resumed
  run sets up the same factors and repeats the uninterrupted run bit for bit;
- the *stable-step estimate* :math:`\lambda_{min}(M_L^{-1} M_C)` (Lanczos coefficients of CG,
  :meth:`fempm.transfer.Projector.mass_ratio_min`) on the system without slip constraints,
  refreshed when asked (every step when the step size is the stable one).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from dolfinx.cpp.common import create_sub_index_map
from mpi4py import MPI
from petsc4py import PETSc

from fempm import petsc as fpetsc
from fempm.kernels import consistent as kc
from fempm.stepping.mass_options import ksp_options
from fempm.stepping.mass_sparsity import cells_around, entries
from fempm.stepping.nodal import kept_nodal_array
from fempm.stepping.options import SimulationError
from fempm.transfer.mapping import SUPPORT_TOL
from fempm.transfer.mass_span import (check_nonsingular, mass_ratio_estimate, mass_ratio_ksp, mass_ratio_rhs,
                                      share_flags)

__all__ = ["REFRESH_GROWTH", "ConsistentSystems"]

#: the preconditioner is set up again when a solve takes more than this factor times the
#: iterations it took fresh (plus 2), and whenever the sparsity, the occupied cells, the
#: supported or the lumped dofs change
REFRESH_GROWTH = 1.5


@dataclass(eq=False)
class _System:
    """One matrix: the dofs it solves for (``free``: owned + ghost), the velocity components
    it serves, and its KSP and vectors."""

    free: npt.NDArray[np.bool_]
    components: list[int]
    ksp: PETSc.KSP
    matrix: PETSc.Mat | None = None
    x: PETSc.Vec | None = None
    b: PETSc.Vec | None = None
    keep: npt.NDArray[np.bool_] | None = None  # this step's dofs solved for (supported and free)
    refresh: bool = True  # set the preconditioner up from the current values at the next solve
    fresh_iterations: int = 0  # KSP iterations of the first solve (of > 0) with a fresh preconditioner
    values: npt.NDArray | None = None  # the matrix's COO values of this step
    factored: npt.NDArray | None = None  # the values its preconditioner was set up from
    current: bool = False  # the matrix holds ``values`` (not yet ``factored``)


class ConsistentSystems:
    """The kept consistent mass systems of a vector space of degree 1 or 2 (see the module).

    ``cell_dofs`` (cells, k): the dofmap; ``free`` (dofs, d): which dof components are solved
    for (False on Dirichlet dofs and, per component, on axis-normal slip walls); ``fixed``
    (dofs,): the Dirichlet dofs (excluded from the stable-step system too); ``V``: the space
    (dof coordinates of the stable-step estimate's right-hand side); ``always_lumped`` (dofs,):
    dofs whose rows are lumped whatever their mass (the walls' of node-local conditions,
    :attr:`fempm.stepping.ExplicitSolver.node_local_dofs`); ``nonnegative``: whether the basis
    is (else, P2 Lagrange, the stable-step estimate is preconditioned by the diagonal, as
    :meth:`fempm.transfer.Projector.mass_ratio_min`); ``layer_dofs`` (cells, k): the dofmap when
    ``cell_dofs`` are not the cells' own dofs but a superset per cell (particle domains: the
    dofs of each cell's vertex star, :mod:`fempm.kernels.consistent_domains`), whose blocks
    carry no null-direction test."""

    def __init__(self, V, cell_dofs: npt.NDArray[np.int32], free: npt.NDArray[np.bool_],
                 fixed: npt.NDArray[np.bool_], *, prefix: str, lump_below: float,
                 always_lumped: npt.NDArray[np.bool_] | None = None, nonnegative: bool = True,
                 layer_dofs: npt.NDArray[np.int32] | None = None):
        #: the cells' dofs of the layer around the occupied cells (the dofmap), if not ``cell_dofs``
        self.layer_dofs = cell_dofs if layer_dofs is None else layer_dofs
        #: whether the particle pass sums blocks per cell (point particles: the singularity tests
        #: look for their null directions) or, with ``layer_dofs`` (particle domains: the count
        #: test alone), the matrix's entries through :attr:`slot`
        self.by_entries = layer_dofs is not None
        self.index_map = V.dofmap.index_map
        self.nonnegative = nonnegative
        self.comm = self.index_map.comm
        self.cell_dofs = cell_dofs
        self.num_owned = self.index_map.size_local
        self.num_dofs = self.num_owned + self.index_map.num_ghosts
        self.num_cells = V.mesh.topology.index_map(V.mesh.topology.dim).size_local
        self.lump_below = lump_below
        self.always_lumped = always_lumped  # dofs whose rows are lumped in any case (node-local conditions)
        self.prefix = prefix
        self.ksp_options = ksp_options(self.comm.size, V.mesh.topology.cell_type, nonnegative, layer_dofs is not None)
        base = ~fixed
        self.systems: list[_System] = []
        for c in range(free.shape[1]):  # components with the same constrained dofs share a matrix
            col = free[:, c] & base
            for s in self.systems:
                if not self.comm.allreduce(bool(np.any(s.free != col)), op=MPI.LOR):
                    s.components.append(c)
                    break
            else:
                self.systems.append(_System(col, [c], self._create_ksp()))
        same = [not self.comm.allreduce(bool(np.any(s.free != base)), op=MPI.LOR) for s in self.systems]
        self.base = self.systems[same.index(True)] if any(same) else _System(base, [], None)
        self._ratio_ksp: PETSc.KSP | None = None
        self._ratio_rhs: npt.NDArray | None = None  # over all owned dofs, made on first use
        self.pattern = np.full(len(cell_dofs), -1, dtype=np.int32)  # cell -> its row in the blocks (-1: outside)
        self.pattern_cells = np.zeros(0, dtype=np.int32)
        self.nnz = 0  #: the number of entries of the sparsity
        #: the cells (local) that keep their star dofs by star dofs (particle domains reaching beyond
        #: the pairs of :mod:`fempm.stepping.mass_sparsity`), for the run
        self.wide = np.zeros(0, dtype=np.int32)
        k = cell_dofs.shape[1]
        #: each pattern cell's entries: entry (a, b) of its block is the sparsity's ``slot[q, a, b]``
        self.slot = np.zeros((0, k, k), dtype=np.int32)
        self._pattern_dofs = np.zeros((0, k), dtype=np.int32)
        self._cells_of: tuple | None = None  # the cells of each dof in the pattern (made with it)
        self._base_values_stale = True
        self._blocks: npt.NDArray | None = None
        self._count = np.zeros(0, dtype=np.int64)
        vec, column = kept_nodal_array(self.index_map, 1)
        self._diagonal = (vec, column[:, 0])
        self._structure: tuple | None = None  # (occupied, active, lump) of the last singularity test
        self.active = np.zeros(self.num_dofs, dtype=np.bool_)
        self.lump = np.zeros(self.num_dofs, dtype=np.bool_)
        self.iterations: list[int] = []
        self.rebuilds = 0  # sparsity builds, for diagnostics
        self.tests = 0  # singularity tests, for diagnostics

    def _create_ksp(self) -> PETSc.KSP:
        """A KSP of the options prefix with :attr:`ksp_options`; CG stops on the true residual
        (see :data:`KSP_OPTIONS`) where the prefix does not set the norm."""
        ksp = fpetsc.create_ksp(self.comm, self.prefix, self.ksp_options)
        if ksp.getType() == PETSc.KSP.Type.CG and not PETSc.Options().hasName(self.prefix + "ksp_norm_type"):
            ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
        return ksp

    # -- sparsity -----------------------------------------------------------------------------
    def work_arrays(self, fill: bool = True) -> tuple[npt.NDArray, npt.NDArray, npt.NDArray, tuple]:
        """Zeroed (blocks (pattern cells, k, k), or with :attr:`by_entries` the entries (nnz + 1,),
        diagonal (dofs,), count (pattern cells,)) for :func:`fempm.kernels.consistent.cell_mass`
        (:func:`fempm.kernels.consistent_domains.domain_cell_mass`), and the diagonal's vector
        (ghost sums); ``fill=False``: as the pass left them."""
        k = self.cell_dofs.shape[1]
        nq = len(self.pattern_cells)
        shape = (self.nnz + 1,) if self.by_entries else (nq, k, k)  # (and the pairs not kept)
        if self._blocks is None or self._blocks.shape != shape or len(self._count) != nq:
            self._blocks = np.empty(shape)
            self._count = np.empty(nq, dtype=np.int64)
            fill = True
        if fill:
            self._blocks.fill(0.0)
            self._count.fill(0)
            self._diagonal[1].fill(0.0)
        return self._blocks, self._diagonal[1], self._count, self._diagonal

    def rebuild(self, particle_cells: npt.NDArray[np.int32]) -> None:
        """Sparsity of the cells holding particles and one layer around them (cells sharing a
        dof with them), on a sub index map of their dofs. Collective."""
        self._build(cells_around(self.layer_dofs[: self.num_cells], np.unique(particle_cells), self.num_dofs,
                                 self.index_map))

    def _build(self, cells: npt.NDArray[np.int32]) -> None:
        """The sparsity of the cells ``cells`` (owned), matrices and vectors. Collective."""
        pattern_dofs = np.ascontiguousarray(self.cell_dofs[cells])  # (cells, k)
        dofs = np.zeros(self.num_dofs, dtype=np.bool_)
        dofs[pattern_dofs.ravel()] = True
        dofs = share_flags(self.index_map, dofs)
        self.sub_map, self.sub_to_parent = create_sub_index_map(self.index_map, np.flatnonzero(dofs).astype(np.int32),
                                                                False)
        n_sub = self.sub_map.size_local
        self.owned_parent = np.ascontiguousarray(self.sub_to_parent[:n_sub])
        parent_to_sub = np.full(self.num_dofs, -1, dtype=np.int64)
        parent_to_sub[self.sub_to_parent] = np.arange(len(self.sub_to_parent))
        width = len(self.sub_to_parent)
        own = wide = None
        if self.by_entries:  # a cell's own dofs by its star dofs, and the wide cells' star by star
            own = parent_to_sub[self.layer_dofs[cells]]
            wide = np.isin(cells, self.wide)
        unique, self.slot = entries(parent_to_sub[pattern_dofs], width, n_sub, own, wide)
        rows, cols = unique // width, unique % width
        # each entry's row and column dofs and the slot of its row's diagonal (the values of entries)
        self._entry_dofs = (self.sub_to_parent[rows].astype(np.int32), self.sub_to_parent[cols].astype(np.int32),
                            np.searchsorted(unique, rows * (width + 1)).astype(np.int32))
        self.diagonal_slot = np.searchsorted(unique, np.arange(n_sub) * (width + 1)).astype(np.int32)
        self.pattern_cells = cells
        self._pattern_dofs = pattern_dofs
        self._cells_of = kc.adjacency(pattern_dofs, self.num_dofs)  # of the singularity tests
        self.pattern = np.full(len(self.cell_dofs), -1, dtype=np.int32)  # cell -> its row in the blocks
        self.pattern[cells] = np.arange(len(cells), dtype=np.int32)
        self.nnz = len(rows)
        lgmap = fpetsc.local_to_global_map(self.sub_map)
        for s in self._all():
            if s.matrix is not None:
                for obj in (s.matrix, s.x, s.b):
                    obj.destroy()
            s.matrix = fpetsc.coo_pattern(self.sub_map, rows, cols, lgmap)
            s.x, s.b = s.matrix.createVecs()
            s.values = s.factored = None
            s.current = False
            if s.ksp is not None:
                s.ksp.reset()  # new sizes
                s.ksp.setOperators(s.matrix)
            s.refresh = True
        self._structure = None
        self.rebuilds += 1

    def _all(self) -> list[_System]:
        return self.systems + ([self.base] if self.base not in self.systems else [])

    # -- values -------------------------------------------------------------------------------
    def update(self, diagonal: npt.NDArray, lumped: npt.NDArray, num_particles: int) -> None:
        r"""New values from the blocks and counts of :meth:`work_arrays` (filled by the particle
        pass), the diagonal :math:`\sum_p M_p N_{ip}^2` and lumped masses (owned + ghost dofs,
        summed over ranks): the supported dofs (diagonal above
        :data:`fempm.transfer.SUPPORT_TOL` of the largest), the lumped dofs (lumped mass below
        ``lump_below`` of the largest), the singularity tests when these or the occupied cells
        changed, and the values of every matrix. Collective."""
        top = np.array([diagonal[: self.num_owned].max(initial=0.0), lumped[: self.num_owned].max(initial=0.0)])
        self.comm.Allreduce(MPI.IN_PLACE, top, op=MPI.MAX)
        self.active = (diagonal > SUPPORT_TOL * top[0]) & self.base.free
        self.lump = lumped < self.lump_below * top[1] if self.lump_below > 0.0 else np.zeros(self.num_dofs, bool)
        if self.always_lumped is not None:
            self.lump |= self.always_lumped
        occupied = np.flatnonzero(self._count)
        prev = self._structure
        changed = (prev is None or not np.array_equal(prev[0], occupied) or not np.array_equal(prev[1], self.active)
                   or not np.array_equal(prev[2], self.lump))
        if self.comm.allreduce(changed, op=MPI.LOR):
            # the empty cells' blocks are 0: they determine nothing, and no copy of the others
            check_nonsingular(self.index_map, num_particles, self.active, self.lump,
                              None if self.by_entries else (self.pattern_cells, self._pattern_dofs, self._blocks),
                              self._cells_of)
            self._structure = (occupied, self.active, self.lump)
            self.tests += 1
            for s in self.systems:  # a few changed rows cost more iterations than a new set-up
                s.refresh = True
        systems = self._all()
        keeps = [self.active & t.free for t in systems]
        n = len(systems)
        differs = np.array([[j < i and bool(np.any(keeps[i] != keeps[j])) for j in range(n)] for i in range(n)])
        self.comm.Allreduce(MPI.IN_PLACE, differs, op=MPI.LOR)
        # a system whose dofs solved for are those of an earlier one (constraints outside the
        # supported dofs) uses its matrix
        self._matrix_of = [next(j for j in range(i + 1) if j == i or not differs[i, j]) for i in range(n)]
        for i, t in enumerate(systems):
            t.keep = keeps[i]
            if self._matrix_of[i] == i and t.components:
                self._set_values(t)
        self._base_values_stale = True

    def _set_values(self, s: _System) -> None:
        if s.values is None:
            s.values = np.empty(self.nnz)
        if self.by_entries:
            kc.coo_entry_values(self._blocks[: self.nnz], *self._entry_dofs, s.keep, self.lump, self.owned_parent,
                                self.diagonal_slot, s.values)
        else:
            kc.coo_values(self._blocks, self.pattern_cells, self.cell_dofs, s.keep, self.lump, self.slot,
                          self.owned_parent, self.diagonal_slot, s.values)
        s.matrix.setValuesCOO(s.values, addv=PETSc.InsertMode.INSERT_VALUES)
        s.current = True

    def _set_up(self, s: _System) -> None:
        """The preconditioner of ``s`` set up now from the matrix's values, blocks included,
        then reused until the next refresh; the values are kept as ``s.factored``. A matrix
        whose values it was already set up from is left as it is (PETSc would too)."""
        if s.current or s.factored is None:
            with fpetsc.temporary_options(self.prefix, self.ksp_options):  # a set-up reads the sub-block options
                fpetsc.set_up_now(s.ksp)
            s.factored, s.values = s.values, s.factored
            s.current = False
        s.refresh, s.fresh_iterations = False, 0

    # -- solves -------------------------------------------------------------------------------
    def solve(self, rhs: npt.NDArray, col: int, out: npt.NDArray, guess: npt.NDArray | None = None) -> None:
        """``out`` (owned + ghost dofs, d) <- the solution of ``m u = rhs[:, col:col+d]`` on the
        solved-for dofs of each component, 0 elsewhere, on owned dofs (ghosts: the caller
        updates them). ``guess`` (dofs, d) warm-starts the KSPs."""
        out[: self.num_owned] = 0.0
        sel = self.owned_parent
        self.iterations = []
        systems = self._all()
        for i, own in enumerate(self.systems):
            s = systems[self._matrix_of[i]]
            if s.refresh:
                self._set_up(s)
            most = 0
            for c in own.components:
                kc.to_system(rhs, col + c, sel, s.keep, s.b.array)
                if guess is None:
                    s.x.set(0.0)
                else:
                    kc.to_system(guess, c, sel, s.keep, s.x.array)
                reason = fpetsc.solve_from(s.ksp, s.b, s.x, guess is not None)
                if reason < 0:
                    raise SimulationError(
                        f"consistent mass solve: KSP did not converge ({fpetsc.converged_reason_name(reason)}, "
                        f"{s.ksp.getIterationNumber()} iterations); the particle mass matrix may be singular")
                self.iterations.append(s.ksp.getIterationNumber())
                most = max(most, self.iterations[-1])
                kc.from_system(s.x.array, sel, c, out)
            if s.fresh_iterations == 0:  # the first solve (of any iterations) since the set-up
                s.fresh_iterations = most
            elif most > REFRESH_GROWTH * s.fresh_iterations + 2:
                s.refresh = True

    # -- checkpoints -------------------------------------------------------------------------
    def state(self) -> dict[str, npt.NDArray]:
        """What a resumed run needs to continue bit for bit (this rank's arrays): the sparsity's
        cells, the values each preconditioner was set up from, the last singularity test's
        structure and the counters (with particle domains, the wide cells). See :meth:`restore`."""
        systems = self._all()
        out = {"pattern_cells": self.pattern_cells, "wide": self.wide,
               "counters": np.array([self.rebuilds] + [s.refresh for s in systems]
                                    + [s.fresh_iterations for s in systems], dtype=np.int64)}
        for i, s in enumerate(systems):
            if s.factored is not None:
                out[f"factored{i}"] = s.factored
        if self._structure is not None:
            out.update(occupied=self._structure[0], active=self._structure[1], lump=self._structure[2])
        return out

    def restore(self, state: dict[str, npt.NDArray]) -> None:
        """The sparsity, preconditioners and counters of :meth:`state`, written by a run on as
        many ranks: each preconditioner set up again from the same values gives the same
        factors, so the next solves repeat those of the run that wrote them. Collective."""
        if "pattern_cells" not in state:
            return
        cells = np.asarray(state["pattern_cells"], dtype=np.int32)
        self.wide = np.asarray(state.get("wide", self.wide), dtype=np.int32)
        if not self.comm.allreduce(len(cells)):  # written before the first step: built then
            return
        self._build(cells)
        systems = self._all()
        counters = state["counters"]
        n = len(systems)
        self.rebuilds = int(counters[0])
        for i, s in enumerate(systems):
            values = state.get(f"factored{i}")
            if values is not None and s.ksp is not None:  # as the run set it up (_set_up)
                s.values = np.array(values)
                s.matrix.setValuesCOO(s.values, addv=PETSc.InsertMode.INSERT_VALUES)
                s.current = True
                self._set_up(s)
            s.refresh = bool(counters[1 + i])
            s.fresh_iterations = int(counters[1 + n + i])
        if "occupied" in state:
            self._structure = (state["occupied"], state["active"].astype(bool), state["lump"].astype(bool))

    def mass_ratio_min(self, V, iterations: int) -> float:
        r"""Estimate of :math:`\lambda_{min}(M_L^{-1} M_C)` on the system without slip
        constraints, as :meth:`fempm.transfer.Projector.mass_ratio_min` (the same right-hand
        side, preconditioner and iterations). Collective."""
        systems = self._all()
        s = systems[self._matrix_of[systems.index(self.base)]]
        if not s.components and self._base_values_stale:  # a matrix of its own, set only here
            self._set_values(s)
            self._base_values_stale = False
        if self._ratio_ksp is None:
            self._ratio_ksp = mass_ratio_ksp(self.comm, iterations, rowsum=self.nonnegative)
            self._ratio_rhs = mass_ratio_rhs(V, np.ones(self.num_owned, dtype=np.bool_))
        self._ratio_ksp.reset()  # the matrix may have new sizes
        keep = s.keep[self.owned_parent]
        s.x.set(1.0)
        s.matrix.mult(s.x, s.b)  # row sums: the lumped masses of the (lumped) matrix
        rows = s.b.array.copy()
        s.b.array[:] = np.where(keep, self._ratio_rhs[self.owned_parent] * np.abs(rows), 0.0)
        return mass_ratio_estimate(self._ratio_ksp, s.matrix, s.b, s.x)

    def destroy(self) -> None:
        for s in self._all():
            for obj in (s.matrix, s.x, s.b, s.ksp):
                if obj is not None:
                    obj.destroy()
        if self._ratio_ksp is not None:
            self._ratio_ksp.destroy()

