"""Timings of the particle-grid operations and peak memory (prints figures; never fails on time).

    python benchmarks/bench_mapping.py                 # 2D 1e5, 2D 1e6, 3D 1e5 (one process each)
    python benchmarks/bench_mapping.py --quick         # 2D 1e5 only
    python benchmarks/bench_mapping.py --dim 2 --n 1e6 # one case
    mpiexec -n 2 python benchmarks/bench_mapping.py --dim 2 --n 1e6

Unstructured gmsh mesh (triangles in 2D, tetrahedra in 3D) with about n / ppc cells; particles
at uniformly random points given on rank 0 (so "location" includes the distribution to the
owning ranks under MPI), P1 space. Stages:

- location: ``Particles(mesh, x, m, v)`` (bounding-box candidates + vectorized pull-back),
- relocation: after a small random move, previous cell first,
- basis: values (and gradients) at the particles,
- lumped P2G: lumped mass and a 2-component momentum,
- consistent assembly: mass matrix from COO data (PETSc),
- solve: active-dof submatrix + KSP (CG + Jacobi), one scalar field.
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import time

import fempm
import dolfinx.fem
import numpy as np
from mpi4py import MPI

from fempm.meshes import unstructured_box, unstructured_rectangle
from fempm.studies.harness import Provenance
from fempm.transfer import consistent_mass_matrix, p2g


def peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def one_case(dim: int, n: int, ppc: int) -> None:
    comm = MPI.COMM_WORLD
    timings: dict[str, float] = {}

    def timed(name, fn):
        comm.Barrier()
        t0 = time.perf_counter()
        out = fn()
        comm.Barrier()
        timings[name] = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
        return out

    ncells_target = n / ppc
    if dim == 2:
        h = np.sqrt(2.0 / ncells_target) * 1.07
        mesh = timed("mesh (gmsh)", lambda: unstructured_rectangle(comm, h))
    else:
        h = (6.0 * np.sqrt(2) / ncells_target) ** (1 / 3) * 1.0
        mesh = timed("mesh (gmsh)", lambda: unstructured_box(comm, h))
    ncells = mesh.topology.index_map(dim).size_global
    rng = np.random.default_rng(0)
    x = rng.random((n, dim)) if comm.rank == 0 else np.zeros((0, dim))
    vol = 1.0 / n
    locator = timed("locator set-up", lambda: fempm.CellLocator(mesh))
    p = timed("location", lambda: fempm.Particles(mesh, x, 1000.0 * vol, vol, locator=locator))
    hmin = h / 20
    p.x = np.clip(p.x + rng.uniform(-hmin, hmin, p.x.shape), 1e-9, 1 - 1e-9)
    timed("relocation", p.relocate)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    timed("basis (values)", lambda: fempm.ParticleBasis(V, p))
    basis = timed("basis (values+gradients)", lambda: fempm.ParticleBasis(V, p, gradients=True))
    vel = np.column_stack([np.sin(p.x[:, 0]), np.cos(p.x[:, 1])])
    timed("lumped P2G (mass + momentum)", lambda: (p2g(basis, p.mass), p2g(basis, p.mass[:, None] * vel)))
    A = timed("consistent assembly", lambda: consistent_mass_matrix(basis, p))
    A.destroy()
    proj = timed("projector set-up (assembly+submatrix+KSP)", lambda: fempm.Projector(V, p, basis=basis))
    f = np.sin(3 * p.x[:, 0]) + p.x[:, 1]
    timed("consistent solve (1 field)", lambda: proj.project(f))
    timed("lumped projection set-up + solve", lambda: fempm.Projector(V, p, basis=basis, mass="lumped").project(f))
    mem = comm.allreduce(peak_mb(), op=MPI.SUM)
    nglob = p.num_global  # collective: outside the rank-0 block
    if comm.rank == 0:
        print(f"\n## {dim}D unstructured {'triangles' if dim == 2 else 'tetrahedra'}: {nglob:,} particles, "
              f"{ncells:,} cells, {V.dofmap.index_map.size_global:,} dofs, {comm.size} rank(s), "
              f"KSP its {proj.iterations[0]}")
        print("| stage | time [s] | M particles/s |\n|---|---|---|")
        for k, t in timings.items():
            rate = "" if k.startswith(("mesh", "locator")) else f"{nglob / t / 1e6:.2f}"
            print(f"| {k} | {t:.3f} | {rate} |")
        print(f"| peak memory (sum over ranks) | {mem:.0f} MB | |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--dim", type=int)
    parser.add_argument("--n", type=float)
    parser.add_argument("--ppc", type=int, default=4)
    parser.add_argument("--quick", action="store_true", help="the 2D case at 1e5 particles only")
    a = parser.parse_args()
    if a.dim is not None:
        one_case(a.dim, int(a.n), a.ppc)
        return
    print(Provenance.now().line(), flush=True)
    for dim, n in [(2, 100_000)] if a.quick else [(2, 100_000), (2, 1_000_000), (3, 100_000)]:
        subprocess.run([sys.executable, __file__, "--dim", str(dim), "--n", str(n), "--ppc", str(a.ppc)], check=True)


if __name__ == "__main__":
    main()
