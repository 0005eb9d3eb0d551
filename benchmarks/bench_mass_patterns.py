"""The consistent mass of particle domains: its kept sparsity against the pairs the particles couple.

    .venv/bin/python benchmarks/bench_mass_patterns.py [--sizes 1e5] [--meshes tri quad]
                                                       [--configs cons-cpdi1 cons-ugimp] [--repeats 5]
                                                       [--reference DIR]

With particle domains the kept systems of the consistent mass
(:class:`fempm.stepping.mass_systems.ConsistentSystems`) hold each cell's star dofs by star dofs
(:func:`fempm.kernels.consistent_domains.star_dofs`), a superset of the pairs of dofs the
particles couple. This script takes one step of the reference problem of
``bench_configurations.py`` (``--configs``: its consistent-domain rows), records the step's
solves (right-hand side, first guess, matrix) and replays them, each preconditioner set up once
as the step does, on

* ``kept``: the kept sparsity, explicit zeros included (what the step solves);
* ``nonzero``: the same matrix without its zero entries (the pairs the step's particles couple);

with incomplete Cholesky of level 0 and 1 and the step's KSP tolerances. Each row gives the
entries a row, the set-up, the iterations of the step's solves, the solves' time, and the
sum of set-up and solves against the step (the fastest of ``--repeats`` replays). It answers
what a sparsity of the coupled pairs would save in the solves, the part of the step that
scales with the entries.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
DEFAULT_REFERENCE = os.environ.get("FEMPM_REFERENCE_MPM", str(HERE.parent.parent / "shared" / "reference-mpm"))


def record_step(solver, dt: float):
    """One step of ``solver`` with its consistent-mass solves recorded: a list of (matrix index,
    b, x0, warm), the matrices' CSR arrays, their KSP's tolerances, and the step's time."""
    import fempm.petsc as fpetsc
    from fempm.stepping import mass_systems

    solves, matrices, keys, tolerances = [], [], [], []
    original = fpetsc.solve_from

    def recording(ksp, b, x, warm):
        A = ksp.getOperators()[0]
        key = A.handle
        if key not in keys:
            keys.append(key)
            matrices.append(tuple(a.copy() for a in A.getValuesCSR()))
            tolerances.append(ksp.getTolerances())
        solves.append((keys.index(key), b.array.copy(), x.array.copy(), warm))
        return original(ksp, b, x, warm)

    mass_systems.fpetsc.solve_from = recording
    try:
        t0 = time.perf_counter()
        solver.step(dt)
        t_step = time.perf_counter() - t0
    finally:
        mass_systems.fpetsc.solve_from = original
    return solves, matrices, tolerances, t_step


def replay(csr, tolerances, solves, index: int, zeros: bool, levels: int, repeats: int) -> dict:
    """The step's solves of matrix ``index`` on its CSR arrays (``zeros``: kept, else dropped
    off the diagonal), ICC(``levels``): the fastest set-up and solves of ``repeats``."""
    import numpy as np
    from petsc4py import PETSc

    ai, aj, av = csr
    n = len(ai) - 1
    rows = np.repeat(np.arange(n), np.diff(ai))
    keep = np.ones(len(av), dtype=bool) if zeros else (av != 0.0) | (rows == aj)
    ip = np.concatenate([[0], np.cumsum(np.bincount(rows[keep], minlength=n))]).astype(PETSc.IntType)
    A = PETSc.Mat().createAIJWithArrays((n, n), (ip, aj[keep].astype(PETSc.IntType), av[keep].copy()),
                                        comm=PETSc.COMM_SELF)
    A.assemble()
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    ksp.setOperators(A)
    ksp.setType("cg")
    ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
    rtol, atol, dtol, maxit = tolerances
    ksp.setTolerances(rtol=rtol, atol=atol, divtol=dtol, max_it=maxit)
    pc = ksp.getPC()
    pc.setType("icc")
    pc.setFactorLevels(levels)
    ksp.setUp()
    b, x = A.createVecs()
    best_setup, best_solves, its = np.inf, np.inf, []
    mine = [s for s in solves if s[0] == index]
    for _ in range(repeats):
        A.setValue(0, 0, av[ai[0]], addv=PETSc.InsertMode.INSERT_VALUES)  # new values: a numeric set-up
        A.assemble()
        t0 = time.perf_counter()
        pc.setUp()
        best_setup = min(best_setup, time.perf_counter() - t0)
        its, total = [], 0.0
        for _, rhs, x0, warm in mine:
            b.array[:] = rhs
            x.array[:] = x0 if warm else 0.0
            ksp.setInitialGuessNonzero(warm)
            t0 = time.perf_counter()
            ksp.solve(b, x)
            total += time.perf_counter() - t0
            its.append(ksp.getIterationNumber())
        best_solves = min(best_solves, total)
    for obj in (A, ksp, b, x):
        obj.destroy()
    return {"entries_per_row": int(keep.sum()) / n, "setup_s": best_setup, "solves_s": best_solves, "its": its}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="+", default=["1e5"])
    ap.add_argument("--meshes", nargs="+", default=["tri", "quad"])
    ap.add_argument("--configs", nargs="+", default=["cons-cpdi1", "cons-ugimp"])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--reference", default=DEFAULT_REFERENCE)
    a = ap.parse_args(argv)
    sys.path.insert(0, str(HERE))
    import fempm  # noqa: F401  (before dolfinx)
    import bench_configurations as bc

    print("| configuration | mesh | particles | sparsity | ICC level | entries a row | set-up [ms] | iterations "
          "| solves [ms] | set-up + solves [ms] | step [ms] |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for size in a.sizes:
        for mesh in a.meshes:
            for name in a.configs:
                solver, dt = bc.reference_problem(int(float(size)), mesh, Path(a.reference), bc.CASES[name])
                for _ in range(3):
                    solver.step(dt)
                steps = [record_step(solver, dt) for _ in range(3)]
                solves, matrices, tolerances, _ = steps[-1]
                t_step = min(s[3] for s in steps)
                for index, csr in enumerate(matrices):
                    for zeros in (True, False):
                        for levels in (0, 1):
                            r = replay(csr, tolerances[index], solves, index, zeros, levels, a.repeats)
                            print(f"| {name} | {mesh} | {solver.particles.num_global} | "
                                  f"{'kept' if zeros else 'nonzero'} | {levels} | {r['entries_per_row']:.1f} | "
                                  f"{1e3 * r['setup_s']:.2f} | {r['its']} | {1e3 * r['solves_s']:.2f} | "
                                  f"{1e3 * (r['setup_s'] + r['solves_s']):.2f} | {1e3 * t_step:.1f} |", flush=True)
    print(f"(`{' '.join(['.venv/bin/python', 'benchmarks/bench_mass_patterns.py'] + (argv or sys.argv[1:]))}`)")


if __name__ == "__main__":
    main()
