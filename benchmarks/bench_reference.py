"""fempm against the reference MPM kernels (numba, Taichi CPU) on the reference problem, in one run.

    python benchmarks/bench_reference.py [--sizes 1e5 1e6] [--ranks 1 2] [--meshes quad tri] [--partition particles]
                                         [--masses lumped consistent] [--check] [--json FILE]
                                         [--reference DIR] [--rounds K]

The problem (``reference-mpm/README.md``): a centred block of side 0.5 in the unit square, 2x2
jittered particles per grid cell, v = 0.5 sin(4 pi x_(k+1)), compressible neo-Hookean
(mu = lambda = 400), gravity, USL, FLIP, lumped mass with a nodal-mass cut-off of 1 % of a
particle's mass, the normal velocity zero on the outer 3 node layers, dt = 0.1 dx / 40. fempm
runs it on structured quadrilaterals (``quad``, the reference grid) and on gmsh triangles of the
same size (``tri``), under ``mpiexec -n R``; the references run with R threads. On several
ranks the mesh is distributed by particles (:func:`fempm.particles.partition.particle_balanced`; DOLFINx's
own partition, by cells, with ``--partition cells``).

Each configuration runs in its own process (a worker: this script with ``--worker``): 3 warm-up
steps, then 7 batches of at least 0.4 s; the median time per step (maximum over ranks) gives
particle-steps per second. Peak memory per particle: the growth of the peak resident set from
after the mesh is built to the end of the run, summed over ranks, over the number of particles.
``--check`` first runs 300 steps at 1e4 particles in fempm and in the numba kernel and compares
the positions (same physics before comparing speed). The speed-up from 1 to R ranks (threads)
of each implementation is printed (and written under ``scaling``); on several ranks, also each
rank's time in the compiled particle passes alone (P2G and G2P, no communication; one more
batch of steps, ``per_rank`` in the rows): the faster ranks wait for the slowest.
``--rounds K`` runs every configuration K times in rounds (the references, then fempm, K times
over) and reports medians: this machine's speed drifts by 20-50 % within minutes, so a ratio is
taken within a round, then its median.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_REFERENCE = Path(os.environ.get("FEMPM_REFERENCE_MPM", ROOT.parent / "shared" / "reference-mpm"))
PPC = 4


# -- the worker: one fempm configuration ---------------------------------------------------------
def _status_kb(key: str) -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    return 0


def _rss_kb() -> int:
    """The resident set now; also resets its peak (Linux: ``clear_refs`` 5), so that the peak
    read by :func:`_peak_kb` is that of what follows (not of the gmsh meshing before it)."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass
    return _status_kb("VmRSS")


def _peak_kb() -> int:
    """Peak resident set since the last :func:`_rss_kb` (``VmHWM``), else since the start."""
    return _status_kb("VmHWM") or resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


def build(n_target: int, mesh_kind: str, mass: str, reference: Path, partition: str = "particles"):
    """The reference problem as a fempm solver; returns (solver, dt, particles, rss after mesh).
    ``partition``: on several ranks, the mesh distributed by particles
    (:func:`fempm.particles.partition.particle_balanced`) or as DOLFINx partitions it (``cells``)."""
    import dolfinx.mesh as dm
    import numpy as np
    from mpi4py import MPI

    import fempm
    from fempm.boundary import slip
    from fempm.materials import NeoHookean
    from fempm.stepping import ExplicitSolver, Loads, StepOptions

    sys.path.insert(0, str(reference))
    from common import init_velocity, seed_block  # the reference's own seeding

    comm = MPI.COMM_WORLD
    x, n_cells, dx, N = seed_block(n_target, PPC, 2)
    if mesh_kind == "quad":
        mesh = dm.create_unit_square(comm, n_cells, n_cells, dm.CellType.quadrilateral)
    else:
        mesh = triangle_mesh(comm, dx)
    if comm.size > 1 and partition == "particles":
        from fempm.particles.partition import particle_balanced

        mesh = particle_balanced(mesh, x if comm.rank == 0 else np.zeros((0, 2)))
    rss0 = _rss_kb()
    vol = dx**2 / PPC
    mine = x if comm.rank == 0 else np.zeros((0, 2))
    p = fempm.Particles(mesh, mine, vol, vol, fields={"v": init_velocity(mine)})
    V = dolfinx_space(mesh)
    band = 3 * dx * (1 + 1e-9)
    bcs = [slip(V, lambda y: (y[0] < band) | (y[0] > 1 - band), (1.0, 0.0)),
           slip(V, lambda y: (y[1] < band) | (y[1] > 1 - band), (0.0, 1.0))]
    opts = StepOptions(scheme="USL", flip=1.0, mass=mass, mass_cutoff=2.5e-3)
    solver = ExplicitSolver(V, p, [NeoHookean(1000.0, 0.25)], bcs=bcs, loads=Loads(body_force=(0.0, -9.8)),
                            options=opts)
    return solver, 0.1 * dx / 40.0, p, rss0


def triangle_mesh(comm, dx: float):
    """gmsh triangles of size ``dx`` on the unit square, from fempm's mesh cache after the first
    run (:mod:`fempm.meshes.cache`: meshed once, not once per worker or per run)."""
    from fempm.meshes import unstructured_rectangle

    return unstructured_rectangle(comm, dx)


def dolfinx_space(mesh):
    import dolfinx.fem

    return dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))


def worker(args) -> None:
    import numpy as np
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    solver, dt, p, rss0 = build(int(float(args.n)), args.mesh, args.mass, Path(args.reference), args.partition)
    N = p.num_global
    if args.check_steps:
        for _ in range(args.check_steps):
            solver.step(dt)
        ids = np.concatenate(comm.allgather(p.ids))
        xs = np.concatenate(comm.allgather(p.x))
        if comm.rank == 0:
            np.save(args.out, xs[np.argsort(ids)])
        return

    def timed(k: int) -> float:
        comm.Barrier()
        t0 = time.perf_counter()
        for _ in range(k):
            solver.step(dt)
        return comm.allreduce(time.perf_counter() - t0, op=MPI.MAX) / k

    timed(3)  # warm-up
    k = max(1, int(0.4 / max(timed(1), 1e-9)))
    times = [timed(k) for _ in range(7)]
    peak = comm.allreduce(max(_peak_kb() - rss0, 0))
    passes = particle_pass_times(solver, dt, k) if comm.size > 1 else None
    if comm.rank == 0:
        med = statistics.median(times)
        print(json.dumps({"impl": f"fempm-{args.mesh}-{args.mass}", "n": N, "ranks": comm.size, "t_step_s": med,
                          "pps": N / med, "peak_kb_per_particle": peak / N, "steps_per_batch": k,
                          "dt": dt, **({"per_rank": passes} if passes else {})}), flush=True)


def particle_pass_times(solver, dt: float, steps: int) -> list[dict]:
    """Each rank's particles and the time a step spends in its compiled particle passes (P2G and
    G2P, no communication), over ``steps`` steps after the timed ones: where the ranks differ in
    speed, the faster waits for the slower in the next collective. Collective."""
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    kernels = solver.grid.kernels
    spent = {"p2g": 0.0, "g2p": 0.0}

    def timer(f, key):
        def g(*a, **kw):
            t0 = time.perf_counter()
            try:
                return f(*a, **kw)
            finally:
                spent[key] += time.perf_counter() - t0
        return g

    originals = kernels.scatter, kernels.g2p_update
    kernels.scatter, kernels.g2p_update = timer(originals[0], "p2g"), timer(originals[1], "g2p")
    try:
        for _ in range(steps):
            solver.step(dt)
    finally:
        kernels.scatter, kernels.g2p_update = originals
    mine = {"particles": len(solver.particles), "p2g_ms": 1e3 * spent["p2g"] / steps,
            "g2p_ms": 1e3 * spent["g2p"] / steps}
    return comm.gather(mine)


# -- the driver -----------------------------------------------------------------------------------
def _last_json(text: str) -> dict:
    for line in reversed(text.strip().splitlines()):
        if line.startswith("{"):
            return json.loads(line)
    raise RuntimeError(f"no result line in:\n{text[-2000:]}")


def run_fempm(n: float, mesh: str, mass: str, ranks: int, reference: Path, extra=(), partition="particles") -> dict:
    py, mpiexec = sys.executable, str(Path(sys.executable).with_name("mpiexec"))
    cmd = [mpiexec, "-n", str(ranks), py, __file__, "--worker", "--n", str(n), "--mesh", mesh, "--mass", mass,
           "--reference", str(reference), "--partition", partition, *extra]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
    r = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if r.returncode:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{r.stderr[-3000:]}")
    return _last_json(r.stdout) if not extra else {}


def run_reference(impl: str, n: float, threads: int, reference: Path, env_extra=None, cwd=None) -> dict:
    script = {"numba": ["numba_mpm.py", str(n), str(PPC), str(threads)],
              "taichi": ["taichi_mpm.py", "usl-linear", "2", str(n), str(PPC), str(threads)]}[impl]
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "PERF_RESULTS": str(Path(tmp) / "results.jsonl"), **(env_extra or {})}
        r = subprocess.run([sys.executable, str(reference / script[0]), *script[1:]], capture_output=True, text=True,
                           env=env, cwd=cwd or tmp)
    if r.returncode:
        raise RuntimeError(f"{impl} reference failed:\n{r.stderr[-3000:]}")
    return _last_json(r.stdout) if env_extra is None else {}


def check_physics(reference: Path, steps: int = 300, n: float = 1e4) -> dict:
    """Positions after ``steps`` steps at ``n`` particles: fempm (quads, lumped) against numba."""
    import numpy as np

    with tempfile.TemporaryDirectory() as tmp:
        mine = Path(tmp) / "fempm.npy"
        run_fempm(n, "quad", "lumped", 1, reference, extra=("--check-steps", str(steps), "--out", str(mine)))
        run_reference("numba", n, 1, reference, env_extra={"PERF_CHECK": str(steps)}, cwd=tmp)
        ref = np.load(next(Path(tmp).glob("check_numba_*.npy")))
        x = np.load(mine)
        sys.path.insert(0, str(reference))
        from common import seed_block

        x0 = seed_block(n, PPC, 2)[0]
    diff = np.linalg.norm(x - ref, axis=1)
    disp = np.linalg.norm(ref - x0, axis=1)
    return {"steps": steps, "particles": len(x), "median_diff": float(np.median(diff)), "max_diff": float(diff.max()),
            "median_displacement": float(np.median(disp))}


def measure(n: float, ranks: int, a) -> list[dict]:
    """The rows of one size and rank count: ``a.rounds`` rounds, each running every reference and
    every fempm configuration once, one after the other. A row's step time is the median over
    the rounds; its ratios to the references are the medians of the ratios within a round (runs
    close in time, on a machine whose speed drifts), with their range over the rounds."""
    per_round = []
    for k in range(a.rounds):
        refs = {impl: run_reference(impl, n, ranks, a.reference) for impl in a.references}
        rows = [{"impl": impl, "n": res["n"], "ranks": ranks, "pps": res["pps_median"],
                 "t_step_s": res["t_step_median_s"]} for impl, res in refs.items()]
        for mesh in a.meshes:
            for mass in a.masses:
                res = run_fempm(n, mesh, mass, ranks, a.reference, partition=a.partition)
                res["vs"] = {impl: res["pps"] / ref["pps_median"] for impl, ref in refs.items()}
                rows.append(res)
                print(json.dumps({**res, "round": k + 1}), flush=True)
        per_round.append(rows)
    if a.rounds == 1:
        return per_round[0]
    merged = []
    for i, first in enumerate(per_round[0]):
        runs = [rows[i] for rows in per_round]
        t = statistics.median(row["t_step_s"] for row in runs)
        row = {**first, "t_step_s": t, "pps": first["n"] / t, "rounds": runs}
        if "peak_kb_per_particle" in first:
            row["peak_kb_per_particle"] = max(run["peak_kb_per_particle"] for run in runs)
        if "vs" in first:
            row["vs"] = {impl: statistics.median(run["vs"][impl] for run in runs) for impl in first["vs"]}
            row["vs_range"] = {impl: [min(run["vs"][impl] for run in runs), max(run["vs"][impl] for run in runs)]
                               for impl in first["vs"]}
        merged.append(row)
    return merged


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=float, nargs="+", default=[1e5, 1e6])
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--meshes", nargs="+", default=["quad", "tri"], choices=["quad", "tri"])
    ap.add_argument("--masses", nargs="+", default=["lumped", "consistent"], choices=["lumped", "consistent"])
    ap.add_argument("--references", nargs="*", default=["numba", "taichi"], choices=["numba", "taichi"])
    ap.add_argument("--check", action="store_true", help="compare positions after 300 steps with the numba kernel first")
    ap.add_argument("--rounds", type=int, default=1,
                    help="run every configuration this many times, in rounds; medians, and ratios within a round")
    ap.add_argument("--json", type=Path, help="write the figures to this file")
    ap.add_argument("--reference", type=Path, default=DEFAULT_REFERENCE, help="the reference-mpm folder")
    ap.add_argument("--partition", default="particles", choices=["particles", "cells"],
                    help="on several ranks: the mesh distributed by particles (fempm.particles.partition) or by cells (DOLFINx)")
    # worker mode (one configuration under mpiexec)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--n", default="1e4", help=argparse.SUPPRESS)
    ap.add_argument("--mesh", default="quad", help=argparse.SUPPRESS)
    ap.add_argument("--mass", default="lumped", help=argparse.SUPPRESS)
    ap.add_argument("--check-steps", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--out", default="", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        import fempm  # noqa: F401  (dolfinx_solver before dolfinx)

        worker(a)
        return
    if not (a.reference / "common.py").exists():
        raise SystemExit(f"bench_reference: no reference kernels in {a.reference} (set --reference or FEMPM_REFERENCE_MPM)")
    out = {"check": None, "rows": []}
    if a.check:
        out["check"] = check_physics(a.reference)
        c = out["check"]
        print(f"physics check, {c['particles']} particles, {c['steps']} steps: |x_fempm - x_numba| median "
              f"{c['median_diff']:.2e}, max {c['max_diff']:.2e}; median displacement {c['median_displacement']:.2e}")
    for n in a.sizes:
        for r in a.ranks:
            out["rows"] += measure(n, r, a)
    print("\n| implementation | particles | ranks/threads | particle-steps/s | step [s] | vs numba | vs Taichi | kB/particle |")
    print("|---|---|---|---|---|---|---|---|")
    for row in out["rows"]:
        vs, spread = row.get("vs", {}), row.get("vs_range", {})

        def ratio(impl, vs=vs, spread=spread):
            lo, hi = spread.get(impl, (None, None))
            return f"{vs.get(impl, float('nan')):.2f}" + (f" ({lo:.2f}-{hi:.2f})" if lo is not None else "")

        print(f"| {row['impl']} | {row['n']} | {row['ranks']} | {row['pps']:.3g} | {row['t_step_s']:.4g} | "
              f"{ratio('numba')} | {ratio('taichi')} | {row.get('peak_kb_per_particle', float('nan')):.2f} |")
    if a.rounds > 1:
        print(f"({a.rounds} rounds: medians; the ratios are medians of the ratios within a round, their range in "
              "brackets; kB/particle the largest)")
    for n in a.sizes:
        for r in a.ranks:
            for mesh in a.meshes:
                pair = {row["impl"]: row for row in out["rows"] if row["n"] and row["ranks"] == r
                        and row["impl"].startswith(f"fempm-{mesh}") and abs(row["n"] - n) < 0.2 * n}
                lumped, consistent = pair.get(f"fempm-{mesh}-lumped"), pair.get(f"fempm-{mesh}-consistent")
                if lumped and consistent:
                    per_second = [row["t_step_s"] / row["dt"] for row in (consistent, lumped)]
                    print(f"consistent / lumped step time, {mesh}, {lumped['n']} particles, {r} rank(s): "
                          f"{consistent['t_step_s'] / lumped['t_step_s']:.2f}; wall time per simulated second "
                          f"{per_second[0]:.4g} s / {per_second[1]:.4g} s = {per_second[0] / per_second[1]:.2f}")
    for row in out["rows"]:  # the ranks' particle passes, without communication (fempm, several ranks)
        runs = row.get("rounds", [row])
        if all("per_rank" in run for run in runs):
            each = [[r["p2g_ms"] + r["g2p_ms"] for r in run["per_rank"]] for run in runs]
            print(f"particle passes per rank, {row['impl']}, {row['n']} particles, {row['ranks']} ranks "
                  f"[ms a step]: " + "; ".join(", ".join(f"{t:.1f}" for t in ts) for ts in each)
                  + f" (slowest over fastest rank {', '.join(f'{max(ts) / min(ts):.2f}' for ts in each)})")
    out["scaling"] = []  # one rank's (thread's) step time over R ranks' (threads'), same size and kind
    for row in out["rows"]:
        one = [q for q in out["rows"] if q["impl"] == row["impl"] and q["ranks"] == 1 and q["n"] == row["n"]]
        if row["ranks"] > 1 and one and row.get("t_step_s"):
            speedup = one[0]["t_step_s"] / row["t_step_s"]
            out["scaling"].append({"impl": row["impl"], "n": row["n"], "ranks": row["ranks"], "speedup": speedup})
            print(f"{row['ranks']} ranks/threads over 1, {row['impl']}, {row['n']} particles: {speedup:.2f}x")
    provenance = _provenance(argv)
    out["provenance"] = dataclasses.asdict(provenance)
    print(provenance.line())
    if a.json:
        a.json.write_text(json.dumps(out, indent=1))


def _provenance(argv):
    """The commit, command and date of this run (imported only now: the driver starts MPI, which
    importing fempm does, after its workers have run)."""
    import fempm  # noqa: F401  (dolfinx_solver before dolfinx)
    from fempm.studies.harness import Provenance

    return Provenance.now(command=None if argv is None else shlex.join(["python", __file__, *argv]))


if __name__ == "__main__":
    main()
