"""A large run end to end, as a user runs it: mesh, seeding and location, steps, a frame, a
checkpoint, a resumed run; where the time and the memory go.

    python benchmarks/bench_scale.py [--particles 1e7] [--ranks 2] [--mesh tri|quad] [--refine K]
                                     [--ppc 4] [--out DIR] [--json FILE]

The body: a compressible neo-Hookean block (E = 1e3, nu = 0.25, rho = 1) filling
[0.05, 0.95] x [0.05, 0.80] of the unit square under gravity, ``--ppc`` particles per cell,
seeded by every rank in its own cells (nothing on rank 0 alone), fixed step 0.1 h / c_p. The
mesh: gmsh triangles (``tri``, default) made coarse on rank 0 (cached, :mod:`fempm.meshes.cache`)
and refined ``--refine`` times on every rank (:mod:`fempm.meshes.refinement`), or DOLFINx
quadrilaterals (``quad``). The run (:func:`fempm.scene.run`, under ``mpiexec -n R``): 20 steps
with the particle frames (VTKHDF) at the start and the end and a checkpoint at step 20; then the
scene is built again (as ``python -m fempm resume`` does: the mesh from the cache) and resumed
for 5 more steps.

The JSON (``--json``): ``total_s`` (the worker's wall time from its start to the resumed run's
end, the slowest rank's), ``phases`` (the two runs' ``timings`` added, :mod:`fempm.timings`, and
``resume_build_s``: building the scene again), ``peak_bytes_per_particle`` (the peak resident
sets of all ranks, summed, over the particles: everything the processes hold, Python and
DOLFINx included), ``resumed`` (the resumed run reached step 25 and its particles are those the
first run checkpointed), and the counts.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BODY = ((0.05, 0.95), (0.05, 0.80))
E, NU, RHO, G = 1.0e3, 0.25, 1.0, 9.8
STEPS, MORE = 20, 5


def cells_for(particles: float, ppc: int, mesh: str) -> float:
    """The cell size h that gives about ``particles`` particles in the body."""
    area = (BODY[0][1] - BODY[0][0]) * (BODY[1][1] - BODY[1][0])
    cells = particles / ppc / area  # cells in the body
    per_area = 1.0 if mesh == "quad" else 2.3  # gmsh's triangles of size h: about 2.3 / h^2
    return (per_area / cells) ** 0.5


def build(a, comm):
    """The scene (collective)."""
    import numpy as np

    from fempm.materials import NeoHookean
    from fempm.meshes import structured as dm
    from fempm.meshes import unstructured_rectangle
    from fempm.particles.seeding import create_particles
    from fempm.scene import Scene
    from fempm.stepping import Loads, StepOptions

    h = cells_for(float(a.particles), a.ppc, a.mesh)
    if a.mesh == "quad":
        n = int(round(1.0 / h))
        mesh = dm.create_rectangle(comm, [[0.0, 0.0], [1.0, 1.0]], [n, n], dm.CellType.quadrilateral)
        h = 1.0 / n
    else:
        mesh = unstructured_rectangle(comm, h, refine=a.refine)
    (x0, x1), (y0, y1) = BODY
    p = create_particles(mesh, a.ppc, density=RHO,
                         where=lambda x: (x[0] > x0) & (x[0] < x1) & (x[1] > y0) & (x[1] < y1))
    p.fields["v"] = np.zeros((len(p), 2))
    lam, mu = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))
    dt = 0.1 * h / ((lam + 2 * mu) / RHO) ** 0.5
    return Scene(name="scale", mesh=mesh, particles=p, materials=[NeoHookean(E, NU)], t_end=(STEPS + MORE) * dt,
                 dt=dt, loads=Loads(body_force=(0.0, -G)), options=StepOptions(scheme="USL", flip=1.0), frames=0,
                 outputs=("particles",), params={"particles": a.particles, "mesh": a.mesh, "refine": a.refine})


def worker(a) -> None:
    from mpi4py import MPI

    start = time.perf_counter()
    import fempm  # noqa: F401  (dolfinx_solver before dolfinx)
    from fempm.io.checkpoint import choose
    from fempm.scene import run

    comm = MPI.COMM_WORLD
    out = Path(a.out)
    scene = build(a, comm)
    scene.t_end *= STEPS / (STEPS + MORE)  # the first run: 20 of the 25 steps
    first = run(scene, out, checkpoint_every=STEPS, progress=False, output_limit=None)
    saved = choose(out, comm)[1]
    t = time.perf_counter()
    again = build(a, comm)
    rebuilt = comm.allreduce(time.perf_counter() - t, op=MPI.MAX)
    second = run(again, out, resume=True, progress=False, output_limit=None)
    total = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
    peak = comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)
    phases = {k: first["timings"][k] + second["timings"][k] for k in first["timings"]}
    phases["resume_build_s"] = rebuilt
    n = first["particles"]
    resumed = (second["status"] == "completed" and second["steps"] == STEPS + MORE and saved["step_count"] == STEPS
               and second["particles"] == n)
    if comm.rank == 0:
        print(json.dumps({"total_s": total, "phases": phases, "peak_bytes_per_particle": peak / n,
                          "resumed": bool(resumed), "particles": n, "ranks": comm.size, "steps": second["steps"],
                          "mesh": a.mesh, "refine": a.refine, "ppc": a.ppc,
                          "step_s": (first["timings"]["steps_s"] + second["timings"]["steps_s"]) / (STEPS + MORE - 2)}),
              flush=True)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles", type=float, default=1e7)
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--mesh", choices=["tri", "quad"], default="tri")
    ap.add_argument("--refine", type=int, default=3, help="uniform refinements of the coarse gmsh mesh (tri)")
    ap.add_argument("--ppc", type=int, default=4)
    ap.add_argument("--out", type=Path, default=None, help="the run's folder (default: a temporary one, removed)")
    ap.add_argument("--json", type=Path, help="write the result to this file")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        worker(a)
        return
    tmp = tempfile.TemporaryDirectory(prefix="fempm-bench-scale-") if a.out is None else None
    out = Path(tmp.name) / "run" if tmp else a.out
    py, mpiexec = sys.executable, str(Path(sys.executable).with_name("mpiexec"))
    cmd = [mpiexec, "-n", str(a.ranks), py, __file__, "--worker", "--particles", str(a.particles), "--mesh", a.mesh,
           "--refine", str(a.refine), "--ppc", str(a.ppc), "--out", str(out)]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    if r.returncode:
        raise SystemExit(f"{shlex.join(cmd)} failed:\n{r.stderr[-3000:]}")
    result = json.loads([line for line in r.stdout.splitlines() if line.startswith("{")][-1])
    result["wall_s"] = wall  # with the processes' start (imports, MPI)
    phases = "\n".join(f"  {k:>16}: {v:8.2f} s" for k, v in result["phases"].items())
    print(f"{result['particles']} particles on {result['ranks']} rank(s) ({result['mesh']}, refine {result['refine']}): "
          f"total {result['total_s']:.1f} s (wall {wall:.1f} s), peak {result['peak_bytes_per_particle']:.0f} B/particle, "
          f"step {result['step_s']:.3g} s, resumed: {result['resumed']}\n{phases}")
    if a.json:
        a.json.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
