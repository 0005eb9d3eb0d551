"""Every configuration of the step against the compiled point step, in the same process.

    python benchmarks/bench_configurations.py [--sizes 1e5 1e6] [--meshes tri quad tet hex] [--ranks 1 2]
                                              [--configs NAME ...] [--batches 3] [--min-batch 0.4]
                                              [--json FILE] [--reference DIR]

The problem is the reference problem of ``bench_reference.py`` (a centred block in the unit
square or cube, jittered particles, 4 per cell in 2D and 8 in 3D, compressible neo-Hookean,
gravity, FLIP, slip on the outer node layers, dt = 0.1 dx / 40) on gmsh triangles (``tri``),
structured quadrilaterals (``quad``), DOLFINx tetrahedra (``tet``) or hexahedra (``hex``).
Each configuration differs from the base step, point particles, lumped mass, USL, P1, in one
thing, and is timed against it in the same process, the base and the configuration in
alternating batches (``--batches``, of at least ``--min-batch`` seconds or one step); the ratio
is the median step time of the configuration over the base's, per particle-step (>= 1: slower):

============  ====================================================  ==========================
name          the configuration                                     compared to
============  ====================================================  ==========================
musl          MUSL                                                  the base step
consistent    consistent mass                                       the base step
fmpm2         FMPM(2)                                               the base step
cpdi1         CPDI1 domains                                         the base step
cpdi2         CPDI2 domains (the seeding sub-cells' corners)        the base step
cpdi1-fmpm2   CPDI1 domains, FMPM(2)                                the base step
ugimp         exact uGIMP                                           the base step
cpgimp        exact cpGIMP                                          the base step
apic          APIC (fempm.transfer.transfers)                       the base step (FLIP)
tpic          TPIC                                                  the base step (FLIP)
apic0         APIC without the weak nodes' cutoff (affine_cutoff=0)  the base step (FLIP)
xpic2         XPIC(2)                                               the base step (FLIP)
bernstein2    Bernstein P2, lumped                                  the base step
distorted     quadrilaterals that are not parallelograms (``quad``)  the base step (parallelograms)
point3d       the base step in 3D (``tet``, ``hex``)                the base step on triangles
contact       two disks, ``contact=True``                           the same disks, one field
scene         two disks, ``fempm.run`` (energies, health checks)    the same disks, bare steps
fbar          F-bar (``volumetric="fbar"``)                          the base step
cons-cpdi1    consistent mass, CPDI1 domains                        consistent mass, points
cons-ugimp    consistent mass, exact uGIMP                          consistent mass, points
cons-cpgimp   consistent mass, exact cpGIMP                         consistent mass, points
contact-cons  two disks, ``contact=True``, consistent mass          the same with lumped mass
contact-cons1 two disks, ``contact=True``, consistent mass          the same disks, one field, consistent mass
output        one particle frame, VTKHDF (``fempm.io.vtkhdf``)      the base step
output-vtu    one particle frame, VTK XML pieces (``frame_format``)  the base step
============  ====================================================  ==========================

(``output``: the ratio is the time of one frame of the base step's particles, as a run writes
it, over the time of one step, both of the same particles: "a frame costs that many steps".)
(``contact`` and ``scene``: ``fempm.scenes.two_disks`` on the benchmark's mesh, CFL step, about
the same number of particles.) Each (size, mesh, ranks) runs in its own process under
``mpiexec -n R`` (this script with ``--worker``); a step's time is the slowest rank's. On
more than one rank the reference problem's mesh is distributed by the particles, every cell
sharing a node with a rank's own ghosted there (``particle_balanced(..., ghosts=True)``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from bench_reference import DEFAULT_REFERENCE, triangle_mesh

#: area of the two disks of fempm.scenes.two_disks
DISKS_AREA = 2 * 3.141592653589793 * 0.2**2


@dataclass(frozen=True)
class Case:
    """How a configuration differs from the base step of the reference problem."""

    options: dict = field(default_factory=dict)
    degree: int = 1
    variant: str | None = None
    meshes: tuple[str, ...] = ("tri", "quad", "tet", "hex")
    kind: str = "reference"  # or "distorted", "point3d", "contact", "scene", "output"
    frame_format: str = "vtkhdf"  # kind "output"
    base: dict | None = None  # the base step's options, if not the plain point step's


CASES = {
    "musl": Case({"scheme": "MUSL"}),
    "consistent": Case({"mass": "consistent"}),
    "fmpm2": Case({"mass": "fmpm", "fmpm_order": 2}),
    "cpdi1": Case({"domain": "cpdi1"}),
    "cpdi2": Case({"domain": "cpdi2"}),
    "cpdi1-fmpm2": Case({"domain": "cpdi1", "mass": "fmpm", "fmpm_order": 2}),
    "ugimp": Case({"domain": "ugimp"}),
    "cpgimp": Case({"domain": "cpgimp"}),
    "apic": Case({"transfer": "apic"}),
    "tpic": Case({"transfer": "tpic"}),
    "apic0": Case({"transfer": "apic", "affine_cutoff": 0.0}),
    "xpic2": Case({"transfer": "xpic", "xpic_order": 2}),
    "bernstein2": Case(degree=2, variant="bernstein", meshes=("tri", "tet")),  # basix: simplices only
    "distorted": Case(meshes=("quad",), kind="distorted"),
    "point3d": Case(meshes=("tet", "hex"), kind="point3d"),
    "contact": Case(meshes=("tri", "quad"), kind="contact"),
    "scene": Case(meshes=("tri", "quad"), kind="scene"),
    "fbar": Case({"volumetric": "fbar"}),
    "cons-cpdi1": Case({"mass": "consistent", "domain": "cpdi1"}, base={"mass": "consistent"}),
    "cons-ugimp": Case({"mass": "consistent", "domain": "ugimp"}, base={"mass": "consistent"}),
    "cons-cpgimp": Case({"mass": "consistent", "domain": "cpgimp"}, base={"mass": "consistent"}),
    "contact-cons": Case(meshes=("tri", "quad"), kind="contact-consistent"),
    "contact-cons1": Case(meshes=("tri", "quad"), kind="contact-consistent", base={"contact": False,
                                                                                  "mass": "consistent"}),
    "output": Case(kind="output"),
    "output-vtu": Case(kind="output", frame_format="vtu"),
}


# -- the problems ---------------------------------------------------------------------------------
def make_mesh(comm, kind: str, n_cells: int, dx: float):
    """The background mesh of the unit square or cube."""
    import dolfinx.mesh as dm
    import numpy as np

    if kind == "tri":
        return triangle_mesh(comm, dx)
    if kind in ("quad", "distorted"):
        mesh = dm.create_unit_square(comm, n_cells, n_cells, dm.CellType.quadrilateral)
        if kind == "distorted":  # every interior vertex moved: no cell is a parallelogram
            x = mesh.geometry.x
            s = np.sin(2 * np.pi * x[:, 0]) * np.sin(2 * np.pi * x[:, 1])
            x[:, 0] += 0.15 * dx * s * np.cos(7.0 * x[:, 1] / dx)
            x[:, 1] += 0.15 * dx * s * np.sin(5.0 * x[:, 0] / dx)
        return mesh
    cell = {"tet": dm.CellType.tetrahedron, "hex": dm.CellType.hexahedron}[kind]
    return dm.create_unit_cube(comm, n_cells, n_cells, n_cells, cell)


def space(mesh, degree: int = 1, variant: str | None = None):
    import basix
    import basix.ufl
    import dolfinx.fem

    d = mesh.geometry.dim
    if variant is None:
        return dolfinx.fem.functionspace(mesh, ("Lagrange", degree, (d,)))
    element = basix.ufl.element("Lagrange", mesh.basix_cell(), degree, getattr(basix.LagrangeVariant, variant),
                                shape=(d,))
    return dolfinx.fem.functionspace(mesh, element)


def reference_problem(n_target: int, mesh_kind: str, reference: Path, case: Case = Case()):
    """The reference problem (``bench_reference.build``) in 2D or 3D with ``case``'s options,
    space and mesh; returns (solver, dt). The particles carry their seeding sub-cells'
    half-widths ``lp`` (and corners, for CPDI2)."""
    import numpy as np
    from mpi4py import MPI

    import fempm
    from fempm.boundary import slip
    from fempm.materials import NeoHookean
    from fempm.particles.corners import box_corners
    from fempm.stepping import ExplicitSolver, Loads, StepOptions

    sys.path.insert(0, str(reference))
    from common import init_velocity, seed_block

    comm = MPI.COMM_WORLD
    dim = 3 if mesh_kind in ("tet", "hex") else 2
    ppc = 2**dim
    x, n_cells, dx, _ = seed_block(n_target, ppc, dim)
    mesh = make_mesh(comm, mesh_kind, n_cells, dx)
    if comm.size > 1:  # balanced by particles, every cell sharing a node with a rank's own ghosted there
        from fempm.particles.partition import particle_balanced  # (domains reaching them keep the compiled passes)

        mesh = particle_balanced(mesh, x, ghosts=True)
    mine = x if comm.rank == 0 else np.zeros((0, dim))
    vol = dx**dim / ppc
    lp = np.full_like(mine, 0.25 * dx)  # the 2^d seeding sub-cells' half-widths
    v = np.zeros_like(mine)
    v[:, :2] = init_velocity(mine[:, :2]) if len(mine) else 0.0
    fields = {"v": v, "lp": lp}
    if case.options.get("domain") == "cpdi2":
        fields["corners"] = box_corners(mine, lp)
    p = fempm.Particles(mesh, mine, vol, vol, fields=fields)
    V = space(mesh, case.degree, case.variant)
    band = 3 * dx * (1 + 1e-9)
    bcs = [slip(V, lambda y, a=a: (y[a] < band) | (y[a] > 1 - band), tuple(float(b == a) for b in range(dim)))
           for a in range(dim)]
    opts = StepOptions(**{"scheme": "USL", "flip": 1.0, "mass": "lumped", "mass_cutoff": 2.5e-3, **case.options})
    g = (0.0, -9.8) if dim == 2 else (0.0, -9.8, 0.0)
    solver = ExplicitSolver(V, p, [NeoHookean(1000.0, 0.25)], bcs=bcs, loads=Loads(body_force=g), options=opts)
    return solver, 0.1 * dx / 40.0


def disks_scene(n_target: int, mesh_kind: str, contact: bool, mass: str = "lumped"):
    """``fempm.scenes.two_disks`` on the benchmark's mesh with about ``n_target`` particles."""
    import math

    from mpi4py import MPI

    from fempm.scenes import two_disks

    cells_per_area = 1.0 if mesh_kind == "quad" else 2.3  # gmsh triangles of size h: about 2.3 / h^2
    h = math.sqrt(DISKS_AREA * 4 * cells_per_area / n_target)
    mesh = make_mesh(MPI.COMM_WORLD, mesh_kind, max(1, round(1 / h)), h)
    return two_disks(mesh=mesh, contact=contact, t_end=1e3, frames=0, mass=mass)


# -- timing ---------------------------------------------------------------------------------------
def timed(step: Callable[[], object], k: int, comm) -> float:
    """The slowest rank's mean time of ``k`` calls of ``step``."""
    from mpi4py import MPI

    comm.Barrier()
    t0 = time.perf_counter()
    for _ in range(k):
        step()
    return comm.allreduce(time.perf_counter() - t0, op=MPI.MAX) / k


def per_batch(step, min_batch: float, comm) -> int:
    """Steps per batch: at least ``min_batch`` seconds, at least one step (after 2 warm-ups)."""
    timed(step, 2, comm)
    return max(1, int(min_batch / max(timed(step, 1, comm), 1e-9)))


def compare(base: Callable, step: Callable, batches: int, min_batch: float, comm) -> tuple[float, float]:
    """Median step times (base, configuration) over ``batches`` alternating batches."""
    kb, kc = per_batch(base, min_batch, comm), per_batch(step, min_batch, comm)
    tb, tc = [], []
    for _ in range(batches):
        tb.append(timed(base, kb, comm))
        tc.append(timed(step, kc, comm))
    return statistics.median(tb), statistics.median(tc)


def scene_times(scene, batches: int, min_batch: float, comm) -> list[float]:
    """Step times of ``fempm.run(scene)`` (no output folder: energies and health checks every
    step), from the time between its callbacks, in ``batches`` batches after 3 warm-up steps."""
    import fempm

    stamps: list[float] = []
    solver = scene.solver()
    k = per_batch(solver.step, min_batch, comm)
    need = 3 + batches * k

    class Enough(Exception):
        pass

    def stamp(_solver):
        comm.Barrier()
        stamps.append(time.perf_counter())
        if len(stamps) > need:
            raise Enough

    try:
        fempm.run(scene, progress=False, callback=stamp)
    except Enough:
        pass
    steps = [b - a for a, b in zip(stamps[3:], stamps[4:])]
    return [statistics.mean(steps[i * k:(i + 1) * k]) for i in range(batches)]


def measure(name: str, n: int, mesh: str, a, comm) -> dict | None:
    """One row: the configuration ``name`` against its base, in this process."""
    case = CASES[name]
    if mesh not in case.meshes:
        return None
    ref = Path(a.reference)
    if case.kind == "contact-consistent":
        base_options = case.base or {"contact": True, "mass": "lumped"}
        base = disks_scene(n, mesh, **base_options).solver()
        other = disks_scene(n, mesh, contact=True, mass="consistent").solver()
        tb, tc = compare(base.step, other.step, a.batches, a.min_batch, comm)
        N = base.particles.num_global
        what = (f"two disks, {'contact' if base_options['contact'] else 'one field'}, {base_options['mass']} mass")
        return {"config": name, "mesh": mesh, "n": N, "base_n": N, "t_base_s": tb, "t_s": tc,
                "ratio": tc / tb, "base": what}
    if case.kind in ("contact", "scene"):
        base_scene = disks_scene(n, mesh, contact=False)
        base = base_scene.solver()
        if case.kind == "contact":
            other = disks_scene(n, mesh, contact=True).solver()
            tb, tc = compare(base.step, other.step, a.batches, a.min_batch, comm)
        else:
            kb = per_batch(base.step, a.min_batch, comm)
            before = [timed(base.step, kb, comm) for _ in range(a.batches)]
            runs = scene_times(disks_scene(n, mesh, contact=False), a.batches, a.min_batch, comm)
            after = [timed(base.step, kb, comm) for _ in range(a.batches)]
            tb, tc = statistics.median(before + after), statistics.median(runs)
        N = base.particles.num_global
        return {"config": name, "mesh": mesh, "n": N, "base_n": N, "t_base_s": tb, "t_s": tc,
                "ratio": tc / tb, "base": "two disks, one field, bare step"}
    if case.kind == "output":
        return frame_row(name, n, mesh, case, ref, a, comm)
    if case.kind == "point3d":
        base, dt_b = reference_problem(n, "tri", ref)
        other, dt = reference_problem(n, mesh, ref)
        what = "the base step on triangles"
    elif case.kind == "distorted":
        base, dt_b = reference_problem(n, "quad", ref)
        other, dt = reference_problem(n, "distorted", ref)
        what = "the base step on parallelograms"
    else:
        base, dt_b = reference_problem(n, mesh, ref, Case(case.base) if case.base else Case())
        other, dt = reference_problem(n, mesh, ref, case)
        what = "the base step" if not case.base else f"the step with {case.base}"
    tb, tc = compare(lambda: base.step(dt_b), lambda: other.step(dt), a.batches, a.min_batch, comm)
    nb, nc = base.particles.num_global, other.particles.num_global
    return {"config": name, "mesh": mesh, "n": nc, "base_n": nb, "t_base_s": tb, "t_s": tc,
            "ratio": (tc / nc) / (tb / nb), "compiled": type(other.grid).__name__, "base": what}


def frame_row(name: str, n: int, mesh: str, case: Case, ref: Path, a, comm) -> dict:
    """One row of ``output``: a particle frame of the base step's particles (a run's writer,
    :class:`fempm.io.RunWriter`) against one base step; each frame's file is deleted after it."""
    import shutil

    from fempm.io import RunWriter

    base, dt = reference_problem(n, mesh, ref)
    base.step(dt)  # the fields a run writes
    folder = Path(comm.bcast(tempfile.mkdtemp(prefix="fempm-bench-frames-") if comm.rank == 0 else None))
    writer = RunWriter(folder / "run", base.particles, None, frame_format=case.frame_format)

    def frame():
        writer.write_frame(base.t, base.particles)
        comm.Barrier()
        if comm.rank == 0:
            for old in (folder / "run" / "particles").glob("particles_*"):
                old.unlink()

    try:
        tb, tc = compare(lambda: base.step(dt), frame, a.batches, a.min_batch, comm)
    finally:
        writer.close()
        if comm.rank == 0:
            shutil.rmtree(folder, ignore_errors=True)
    N = base.particles.num_global
    return {"config": name, "mesh": mesh, "n": N, "base_n": N, "t_base_s": tb, "t_s": tc, "ratio": tc / tb,
            "base": "one base step (a frame costs that many steps)"}


def worker(a) -> None:
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    for name in a.configs:
        row = measure(name, int(float(a.n)), a.mesh, a, comm)
        if row is not None and comm.rank == 0:
            print(json.dumps({**row, "ranks": comm.size}), flush=True)


# -- the driver -----------------------------------------------------------------------------------
def run_worker(n: float, mesh: str, ranks: int, a) -> list[dict]:
    py, mpiexec = sys.executable, str(Path(sys.executable).with_name("mpiexec"))
    cmd = [mpiexec, "-n", str(ranks), py, __file__, "--worker", "--n", str(n), "--mesh", mesh,
           "--reference", str(a.reference), "--batches", str(a.batches), "--min-batch", str(a.min_batch),
           "--configs", *a.configs]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
    rows = []
    with subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env) as proc:
        for line in proc.stdout:
            if line.startswith("{"):
                row = json.loads(line)
                rows.append(row)
                print(f"  {row['config']:>10} {row['mesh']:>4} {row['n']:>8} particles, {row['ranks']} rank(s): "
                      f"{row['ratio']:.2f}x", flush=True)
        err = proc.stderr.read()
    if proc.returncode:
        raise RuntimeError(f"{shlex.join(cmd)} failed:\n{err[-3000:]}")
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=float, nargs="+", default=[1e5, 1e6])
    ap.add_argument("--meshes", nargs="+", default=["tri"], choices=["tri", "quad", "tet", "hex"])
    ap.add_argument("--ranks", type=int, nargs="+", default=[1])
    ap.add_argument("--configs", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--batches", type=int, default=3, help="alternating batches per configuration (median)")
    ap.add_argument("--min-batch", type=float, default=0.4, help="seconds a batch lasts at least")
    ap.add_argument("--json", type=Path, help="write the rows to this file")
    ap.add_argument("--reference", type=Path, default=DEFAULT_REFERENCE, help="the reference-mpm folder")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--n", default="1e4", help=argparse.SUPPRESS)
    ap.add_argument("--mesh", default="tri", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.batches < 3:
        ap.error("--batches must be at least 3 (a median of 3 or more)")
    if a.worker:
        import fempm  # noqa: F401  (dolfinx_solver before dolfinx)

        worker(a)
        return
    if not (a.reference / "common.py").exists():
        raise SystemExit(f"bench_configurations: no reference kernels in {a.reference} (their seeding makes the "
                         "problem; set --reference or FEMPM_REFERENCE_MPM)")
    rows = []
    for n in a.sizes:
        for mesh in a.meshes:
            for r in a.ranks:
                rows += run_worker(n, mesh, r, a)
    print("\n| configuration | mesh | particles | ranks | step [ms] | base step [ms] | ratio | compared to |")
    print("|---|---|---|---|---|---|---|---|")
    for row in rows:
        print(f"| {row['config']} | {row['mesh']} | {row['n']} | {row['ranks']} | {1e3 * row['t_s']:.4g} | "
              f"{1e3 * row['t_base_s']:.4g} | {row['ratio']:.2f} | {row['base']} |")
    print("(ratio: the configuration's time per particle-step over its base's, medians of "
          f"{a.batches} alternating batches)")
    import fempm  # noqa: F401  (after the workers: importing fempm starts MPI)
    from fempm.studies.harness import Provenance

    provenance = Provenance.now(command=None if argv is None else shlex.join(["python", __file__, *argv]))
    print(provenance.line())
    if a.json:
        a.json.write_text(json.dumps({"rows": rows, "provenance": dataclasses.asdict(provenance)}, indent=1))


if __name__ == "__main__":
    main()
