"""PETSc helpers, isolated here: matrices from COO data on a DOLFINx index map, active-dof
index sets and KSP set-up with an options prefix."""

from __future__ import annotations

import contextlib
from typing import Any

import dolfinx
import numpy as np
import numpy.typing as npt
from petsc4py import PETSc

__all__ = [
    "DEFAULT_KSP_OPTIONS", "NULL_PIVOT", "converged_reason_name", "coo_matrix", "coo_pattern", "create_ksp",
    "local_to_global_map", "null_pivots", "owned_index_set", "set_up_now", "solve_from", "sub_ksps",
    "temporary_options",
]


def local_to_global_map(index_map: dolfinx.common.IndexMap, bs: int = 1) -> PETSc.LGMap:
    """The local (owned + ghost) to global map of ``index_map``'s blocks of size ``bs``."""
    n = index_map.size_local + index_map.num_ghosts
    g = index_map.local_to_global(np.arange(n, dtype=np.int32)).astype(PETSc.IntType)
    return PETSc.LGMap().create(g, bsize=bs, comm=index_map.comm)


def coo_pattern(
    index_map: dolfinx.common.IndexMap,
    rows: npt.NDArray,
    cols: npt.NDArray,
    lgmap: PETSc.LGMap | None = None,
    bs: int = 1,
    col_bs: int | None = None,
) -> PETSc.Mat:
    """AIJ matrix on ``index_map`` (blocks of ``bs`` rows: local row ``i bs + c`` is
    component ``c`` of dof ``i``; columns likewise in blocks of ``col_bs``, by default ``bs``:
    square) with the sparsity of COO entries in *local* indices (owned + ghost); its values
    come with ``setValuesCOO`` (one per entry, in this order; repeated entries are summed,
    entries in rows owned by another rank are sent there)."""
    cbs = bs if col_bs is None else col_bs
    n, N = index_map.size_local * bs, index_map.size_global * bs
    nc, Nc = index_map.size_local * cbs, index_map.size_global * cbs
    A = PETSc.Mat().create(comm=index_map.comm)
    A.setSizes(((n, N), (nc, Nc)), bsize=bs if cbs == bs else None)
    A.setType(PETSc.Mat.Type.AIJ)
    rmap = lgmap or local_to_global_map(index_map, bs)
    A.setLGMap(rmap, rmap if cbs == bs else local_to_global_map(index_map, cbs))
    A.setPreallocationCOOLocal(
        np.asarray(rows, dtype=PETSc.IntType).ravel().copy(),
        np.asarray(cols, dtype=PETSc.IntType).ravel().copy(),
    )
    return A


def coo_matrix(
    index_map: dolfinx.common.IndexMap,
    rows: npt.NDArray,
    cols: npt.NDArray,
    values: npt.NDArray,
    lgmap: PETSc.LGMap | None = None,
) -> PETSc.Mat:
    """Square AIJ matrix on ``index_map`` from COO entries in *local* indices (owned + ghost),
    see :func:`coo_pattern`."""
    A = coo_pattern(index_map, rows, cols, lgmap)
    A.setValuesCOO(np.asarray(values, dtype=PETSc.ScalarType).ravel(), addv=PETSc.InsertMode.ADD_VALUES)
    A.assemble()
    return A


def owned_index_set(index_map: dolfinx.common.IndexMap, owned_mask: npt.NDArray[np.bool_]) -> PETSc.IS:
    """Global indices of the owned dofs where ``owned_mask`` holds."""
    local = np.flatnonzero(owned_mask).astype(np.int32)
    g = index_map.local_to_global(local).astype(PETSc.IntType)
    return PETSc.IS().createGeneral(g, comm=index_map.comm)


DEFAULT_KSP_OPTIONS: dict[str, Any] = {
    "ksp_type": "cg",
    "pc_type": "jacobi",
    "ksp_rtol": 1e-13,
    "ksp_atol": 1e-300,
    "ksp_max_it": 20000,
}


@contextlib.contextmanager
def temporary_options(prefix: str, values: dict[str, Any]):
    """PETSc options ``values`` under ``prefix`` for the time of the block, where the options
    database (the command line) does not hold them already."""
    opts = PETSc.Options()
    added = [k for k in values if not opts.hasName(prefix + k)]
    for k in added:
        opts[prefix + k] = values[k]
    try:
        yield
    finally:
        for k in added:
            opts.delValue(prefix + k)


def create_ksp(comm, prefix: str, options: dict[str, Any] | None = None) -> PETSc.KSP:
    """KSP with options prefix ``prefix``: fempm defaults (CG + Jacobi), then ``options``, then
    whatever the PETSc options database holds under the prefix (command line wins)."""
    ksp = PETSc.KSP().create(comm)
    ksp.setOptionsPrefix(prefix)
    with temporary_options(prefix, {**DEFAULT_KSP_OPTIONS, **(options or {})}):
        ksp.setFromOptions()
        ksp.getPC().setFromOptions()
    return ksp


def solve_from(ksp: PETSc.KSP, b: PETSc.Vec, x: PETSc.Vec, warm: bool) -> int:
    """``ksp.solve(b, x)`` from the guess in ``x`` (``warm``) or from zero; returns the converged
    reason (an iterative method stopped at its iteration limit: ``DIVERGED_ITS``, whatever the
    type reports). A warm start that PETSc stops at once as diverging (``DIVERGED_DTOL``: its
    residual is far above ``b``, as for forces near equilibrium) is solved again from zero."""
    ksp.setInitialGuessNonzero(warm)
    ksp.solve(b, x)
    reason = _reason(ksp)
    if warm and reason == PETSc.KSP.ConvergedReason.DIVERGED_DTOL:
        ksp.setInitialGuessNonzero(False)
        ksp.solve(b, x)
        reason = _reason(ksp)
    return reason


def _reason(ksp: PETSc.KSP) -> int:
    """The converged reason of the last solve, with ``CONVERGED_ITS`` at the iteration limit of an
    iterative method (GCR reports it so) as ``DIVERGED_ITS``: the tolerance was not reached."""
    reason = ksp.getConvergedReason()
    if (reason == PETSc.KSP.ConvergedReason.CONVERGED_ITS and ksp.getType() != PETSc.KSP.Type.PREONLY
            and ksp.getIterationNumber() >= ksp.getTolerances()[3]):
        return PETSc.KSP.ConvergedReason.DIVERGED_ITS
    return reason


def sub_ksps(ksp: PETSc.KSP) -> list[PETSc.KSP]:
    """The KSPs of a block preconditioner's blocks (block Jacobi, additive Schwarz) once it is
    set up, else none."""
    pc = ksp.getPC()
    try:
        if pc.getType() == PETSc.PC.Type.BJACOBI:
            return list(pc.getBJacobiSubKSP())
        if pc.getType() == PETSc.PC.Type.ASM:
            return list(pc.getASMSubKSP())
    except PETSc.Error:  # not set up yet
        pass
    return []


def set_up_now(ksp: PETSc.KSP) -> None:
    """Set the preconditioner of ``ksp`` up from its operator's current values, blocks included,
    and reuse it from then on (until the next call): its factors are then known to be those of
    these values, and the same whether the KSP was set up before or is new (a resumed run).

    ``KSPSetUp`` of a KSP set up before does not set its preconditioner up again, hence
    ``PCSetUp``; a solve with reuse switched off does not do it either: a solve that converges
    at once never applies the preconditioner, block methods factor their blocks when they are
    first applied, and blocks of a preconditioner that was reused keep being reused."""
    pc = ksp.getPC()
    pc.setReusePreconditioner(False)
    ksp.setUp()
    pc.setUp()
    for sub in sub_ksps(ksp):
        sub.getPC().setReusePreconditioner(False)
    ksp.setUpOnBlocks()
    pc.setReusePreconditioner(True)


def converged_reason_name(reason: int) -> str:
    names = {v: k for k, v in vars(PETSc.KSP.ConvergedReason).items() if isinstance(v, int)}
    return names.get(reason, str(reason))


#: a pivot below this fraction of the matrix norm counts as null in :func:`null_pivots`
NULL_PIVOT = 1e-10


def null_pivots(J: PETSc.Mat) -> int | None:
    r"""The rank deficiency of the assembled matrix ``J`` (an implicit step's tangent, a mass
    matrix): the null pivots of its MUMPS LU factorization with null-pivot detection
    (``ICNTL(24) = 1``, a pivot below :data:`NULL_PIVOT` :math:`\|J\|` null), made apart from
    any solve with ``J`` (whose factorizations stay exact); None without MUMPS. Collective."""
    if not PETSc.Sys.hasExternalPackage("mumps"):
        return None
    ksp = PETSc.KSP().create(J.getComm())
    ksp.setType(PETSc.KSP.Type.PREONLY)
    pc = ksp.getPC()
    pc.setType(PETSc.PC.Type.LU)
    pc.setFactorSolverType("mumps")
    ksp.setOperators(J, J)
    pc.setFactorSetUpSolverType()
    F = pc.getFactorMatrix()
    F.setMumpsIcntl(24, 1)
    F.setMumpsCntl(3, NULL_PIVOT)
    ksp.setUp()
    count = int(F.getMumpsInfog(28))
    ksp.destroy()
    return count
