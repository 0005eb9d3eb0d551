"""Newton's method on PETSc SNES for the implicit step, with the options prefix
``fempm_implicit_`` (:class:`Newton`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from petsc4py import PETSc

from fempm.petsc import NULL_PIVOT, null_pivots, temporary_options  # (the rank test, shared with the masses)

__all__ = ["FORCE_ATOL", "NEWTON_OPTIONS", "NULL_PIVOT", "Newton", "NewtonResult", "null_pivots"]

#: fempm's defaults under the prefix (the options database wins): Newton with a backtracking
#: line search, each linear solve GMRES preconditioned by a parallel LU factorization (MUMPS;
#: for large 3D problems e.g. ``-fempm_implicit_pc_type gamg``); converged at 1e-10 of the
#: first residual, at :data:`FORCE_ATOL` of the forces, or when a Newton step is below 1e-10 of
#: the increment (the round-off floor of a near-incompressible law lies above the others:
#: Cook's membrane at nu = 0.4999 stops at 2e-8 of its first residual)
NEWTON_OPTIONS: dict[str, Any] = {
    "snes_type": "newtonls",
    "snes_linesearch_type": "bt",
    "snes_rtol": 1e-10,
    "snes_atol": 1e-300,
    "snes_stol": 1e-10,  # a Newton step this small against the increment: at the round-off floor (stiff laws)
    "snes_max_it": 25,
    "ksp_type": "gmres",
    "ksp_rtol": 1e-12,
    "pc_type": "lu",
    "pc_factor_mat_solver_type": "mumps",
}


#: a residual below this fraction of the forces it balances has converged (:meth:`Newton.solve`)
FORCE_ATOL = 1e-9



@dataclass
class NewtonResult:
    """What a Newton solve did.

    Attributes:
        converged: whether SNES reports convergence.
        reason: SNES's converged reason (its name).
        iterations: Newton iterations.
        residuals: the residual norm before each iteration and after the last.
    """

    converged: bool
    reason: str
    iterations: int
    residuals: npt.NDArray


class Newton:
    """A SNES with options prefix ``prefix`` (defaults :data:`NEWTON_OPTIONS`, then ``options``,
    then the options database under the prefix).

    Note:
        Construction and :meth:`solve` are collective.
    """

    def __init__(self, comm, prefix: str = "fempm_implicit_", options: dict[str, Any] | None = None):
        self.snes = PETSc.SNES().create(comm)
        self.snes.setOptionsPrefix(prefix)
        self.prefix = prefix
        with temporary_options(prefix, {**NEWTON_OPTIONS, **(options or {})}):
            self.snes.setFromOptions()
            self.snes.getKSP().setFromOptions()
            self.snes.getKSP().getPC().setFromOptions()
            self.snes.getLineSearch().setFromOptions()

    def solve(self, residual: Callable[[PETSc.Vec, PETSc.Vec], None], jacobian: Callable[[PETSc.Vec, PETSc.Mat], None],
              J: PETSc.Mat, x: PETSc.Vec, force_scale: float = 0.0, line_search: str | None = None,
              floor: Callable[[PETSc.Vec], float] | None = None) -> NewtonResult:
        """Solve ``residual(x, r) = 0`` from the guess in ``x`` (the solution left there), with
        ``jacobian(x, J)`` filling the tangent ``J``; ``residual`` may fill ``r`` with infinities
        where ``x`` is outside its domain (the line search then steps back, or the solve fails).
        ``force_scale``: the norm of the forces the residual balances; a residual below
        :data:`FORCE_ATOL` of it has converged (the round-off floor of a small load increment on
        a loaded body lies above the relative tolerance), unless the options database sets
        ``snes_atol``. ``line_search``: a PETSc line search type for this solve instead of the
        configured one (e.g. ``"basic"``: full Newton steps). ``floor``: the round-off floor of the
        residual at an iterate; a solve whose residual lies below it has converged as far as the
        residual can show and stops there (``CONVERGED_ROUND_OFF``, :class:`_ConvergenceTest`:
        near incompressibility the internal forces are differences of terms many times larger,
        and the force tolerance can lie below what they can resolve)."""
        snes = self.snes
        ls = snes.getLineSearch()
        configured = ls.getType()
        if line_search is not None:
            ls.setType(line_search)
        try:
            return self._solve(residual, jacobian, J, x, force_scale, floor)
        finally:
            if line_search is not None:
                ls.setType(configured)
                ls.setFromOptions()  # the options database's settings of the configured search

    def _solve(self, residual, jacobian, J: PETSc.Mat, x: PETSc.Vec, force_scale: float, floor) -> NewtonResult:
        snes = self.snes
        test = _ConvergenceTest(floor)
        snes.setConvergenceTest(test)
        if not PETSc.Options().hasName(self.prefix + "snes_atol"):
            rtol, _, stol, max_it = snes.getTolerances()
            snes.setTolerances(rtol=rtol, atol=max(FORCE_ATOL * force_scale, NEWTON_OPTIONS["snes_atol"]), stol=stol,
                               max_it=max_it)
        r = x.duplicate()
        snes.setFunction(lambda _snes, xx, rr: residual(xx, rr), r)
        def tangent(_snes, xx, A, P) -> None:
            jacobian(xx, P)  # the assembled tangent (with snes_mf_operator the preconditioner's)
            if A.handle != P.handle:  # a matrix-free operator: its base point moves to xx
                A.assemble()

        snes.setJacobian(tangent, J, J)
        snes.setConvergenceHistory(length=snes.getTolerances()[3] + 1, reset=True)
        snes.solve(None, x)
        reason = snes.getConvergedReason()
        norms = np.asarray(snes.getConvergenceHistory()[0], dtype=float).copy()
        names = {v: k for k, v in vars(PETSc.SNES.ConvergedReason).items() if isinstance(v, int)}
        r.destroy()
        snes.setConvergenceTest("default")
        name = "CONVERGED_ROUND_OFF" if test.at_floor and reason > 0 else names.get(reason, str(reason))
        return NewtonResult(reason > 0, name, snes.getIterationNumber(), norms)


class _ConvergenceTest:
    """PETSc's default Newton convergence test (the absolute and relative residual and the step
    tolerances, the divergence tolerance, a non-finite residual), and with a ``floor`` (a
    callable of the iterate) convergence where the residual lies below that round-off floor:
    the solve stops there instead of searching below what the residual can resolve."""

    def __init__(self, floor: Callable[[PETSc.Vec], float] | None):
        self.floor = floor
        self.at_floor = False
        self.target = 0.0  # max(atol, rtol |F_0|)
        self.first = 0.0

    def __call__(self, snes: PETSc.SNES, its: int, norms: tuple[float, float, float]) -> int:
        R = PETSc.SNES.ConvergedReason
        xnorm, ynorm, fnorm = norms
        rtol, atol, stol, _ = snes.getTolerances()
        if its == 0:
            self.first, self.target = fnorm, max(atol, rtol * fnorm)
        if not np.isfinite(fnorm):
            return R.DIVERGED_FUNCTION_NANORINF
        if fnorm < atol:
            return R.CONVERGED_FNORM_ABS
        if its == 0:
            return R.CONVERGED_ITERATING
        if fnorm <= self.target:
            return R.CONVERGED_FNORM_RELATIVE
        if ynorm < stol * xnorm:
            return R.CONVERGED_SNORM_RELATIVE
        divtol = snes.getDivergenceTolerance()
        if divtol > 0 and fnorm > divtol * self.first:
            return R.DIVERGED_DTOL
        if self.floor is not None and fnorm <= self.floor(snes.getSolution()):
            self.at_floor = True
            return R.CONVERGED_FNORM_ABS
        return R.CONVERGED_ITERATING
