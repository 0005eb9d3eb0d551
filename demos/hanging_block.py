r"""# Hanging block under extreme self-weight: standard MPM, GIMP, CPDI1 and CPDI2

A unit block $[0, 1] \times [-1, 0]$ hangs from its top edge (grid velocity zero for
$y > -h/2$) under gravity $g = 1000$: neo-Hookean, $E = 10^6$, $\nu = 0.3$, $\rho = 1050$, so
$\rho g L / E \approx 1$ and the block stretches to about 2.6 times its length before it
swings back (VERIFICATION.md section 6). The grid has cells of size $h = 0.1$ (structured
quadrilaterals, or unstructured triangles with a vertex row on $y = 0$) and each cell starts
with 3 x 3 particles.

* **Standard MPM** (point basis): once a row of particles is more than a cell apart from the
  next, no grid node sees both, and the lower part of the block falls away: an artificial
  fracture.
* **GIMP** (boxes of the initial particle size, 2x2 Gauss points): the boxes only widen the
  reach of a particle by half its spacing, so the block separates as well, slightly later.
* **CPDI1** (parallelograms that follow $F$): each particle's domain covers the gap to its
  neighbours, so the block stays continuous.
* **CPDI2** (each particle is its lattice square, whose four corners move with the grid
  velocity; the particle sits at the square's centroid): the squares keep tiling the block, so
  it stays continuous as well. Its corners follow the grid, not only the particle's $F$: on
  triangles it also survives the rebound (`--t-end 0.5`), where CPDI1's parallelograms, after
  the second swing, reach out of the mesh at t = 0.27.

The measure of continuity is the largest distance between lattice neighbours, in cell sizes
(``fempm.scenes.largest_neighbour_gap``). A run stops early, and says so, when particles leave
the mesh (the separated part falls out of it).

Run: `.venv/bin/python demos/hanging_block.py [--cells 10] [--t-end 0.15] [--out output/hanging_block]`
(also under `mpiexec -n 2`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import fempm  # noqa: F401
import numpy as np
from mpi4py import MPI

from fempm.particles.location import OutsideMeshError
from fempm.scenes import hanging_block, largest_neighbour_gap
from fempm.stepping import SimulationError


def simulate(mesh: str, domain: str, cells: int, t_end: float, snapshot: float, flip: float) -> dict:
    """One run: gap history, the lowest particle, and the particle cloud at ``snapshot``."""
    scene = hanging_block(cells=cells, domain=domain, mesh=mesh, t_end=t_end, flip=flip)
    solver, p, h = scene.solver(), scene.particles, scene.params["h"]
    comm = p.comm
    t, gap, bottom = [0.0], [largest_neighbour_gap(p) / h], [-1.0]
    cloud, stopped = None, ""
    while solver.t < t_end * (1 - 1e-12):
        try:
            solver.step(dt_max=t_end - solver.t)
        except (OutsideMeshError, SimulationError) as e:
            stopped = f"stopped at t = {solver.t:.4f}: {str(e).splitlines()[0][:90]}"
            break
        t.append(solver.t)
        gap.append(largest_neighbour_gap(p) / h)
        bottom.append(comm.allreduce(float(p.x[:, 1].min(initial=np.inf)), op=MPI.MIN))
        if cloud is None and solver.t >= snapshot:
            cloud = _gather(p)
    if cloud is None:
        cloud = _gather(p)
    return {"t": np.array(t), "gap": np.array(gap), "bottom": np.array(bottom), "cloud": cloud,
            "stopped": stopped, "steps": solver.step_count, "extended_steps": solver.extended_steps}


def _gather(p) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Positions, initial lattice rows and (CPDI2) domain corners of all particles (on every rank)."""
    x = np.concatenate(p.comm.allgather(p.x))
    row = np.concatenate(p.comm.allgather(p.fields["lattice"][:, 1]))
    corners = np.concatenate(p.comm.allgather(p.fields["corners"])) if "corners" in p.fields else None
    return x, row, corners


#: the small run its page in the docs shows, executed when the site is built (docs/demo_runs.py)
DOCS_RUN = ["--t-end", "0.08"]


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description="hanging block: point vs GIMP vs CPDI1 vs CPDI2")
    ap.add_argument("--cells", type=int, default=10, help="cells per unit length")
    ap.add_argument("--t-end", type=float, default=0.15)
    ap.add_argument("--snapshot", type=float, default=0.08, help="time of the particle-cloud figure (near the largest stretch)")
    ap.add_argument("--flip", type=float, default=0.99)
    ap.add_argument("--meshes", nargs="+", default=["structured", "unstructured"])
    ap.add_argument("--domains", nargs="+", default=["point", "gimp", "cpdi1", "cpdi2"])
    ap.add_argument("--out", type=Path, default=Path("output/hanging_block"))
    ap.add_argument("--no-plot", action="store_true")
    a = ap.parse_args(argv)
    rank = MPI.COMM_WORLD.rank
    runs = {(m, d): simulate(m, d, a.cells, a.t_end, a.snapshot, a.flip) for m in a.meshes for d in a.domains}
    summary = {f"{m}/{d}": {"max_gap": float(r["gap"].max()), "final_gap": float(r["gap"][-1]),
                            "lowest": float(r["bottom"].min()), "t_reached": float(r["t"][-1]),
                            "stopped": r["stopped"], "steps": r["steps"]} for (m, d), r in runs.items()}
    if rank == 0:
        a.out.mkdir(parents=True, exist_ok=True)
        with open(a.out / "gaps.csv", "w") as fh:
            fh.write("mesh,domain,t,largest_gap_over_h,lowest_y\n")
            for (m, d), r in runs.items():
                for ti, gi, bi in zip(r["t"], r["gap"], r["bottom"]):
                    fh.write(f"{m},{d},{ti:.6g},{gi:.6g},{bi:.6g}\n")
        print(f"hanging block, h = 1/{a.cells}, 3x3 particles per cell, flip {a.flip}:")
        for key, s in summary.items():
            print(f"  {key:24s} largest neighbour gap {s['max_gap']:6.2f} h (at the end {s['final_gap']:.2f} h), "
                  f"lowest point y = {s['lowest']:.3f}, t reached {s['t_reached']:.3f} {s['stopped']}")
        if not a.no_plot:
            _plot(runs, a)
    return summary


def _plot(runs: dict, a) -> None:
    from fempm.io.plot import _pyplot, _save, plot_curves

    plt = _pyplot()
    meshes, domains = a.meshes, a.domains
    fig, axes = plt.subplots(len(meshes), len(domains), figsize=(3.2 * len(domains), 5.2 * len(meshes)), squeeze=False)
    for i, m in enumerate(meshes):
        for j, d in enumerate(domains):
            r = runs[(m, d)]
            x, row, corners = r["cloud"]
            ax = axes[i, j]
            if corners is not None:  # the CPDI2 domains: quadrilaterals, corners in box_corners order
                from matplotlib.collections import PolyCollection

                ax.add_collection(PolyCollection(corners[:, [0, 2, 3, 1]], facecolors="none", edgecolors="0.6", linewidths=0.2))
            ax.scatter(x[:, 0], x[:, 1], c=row, s=1.5, cmap="viridis")
            ax.axhline(0.0, color="k", lw=0.8)
            ax.set_xlim(-0.3, 1.3)
            ax.set_ylim(-4.05, 0.2)
            ax.set_aspect("equal")
            t_snap = min(a.snapshot, r["t"][-1])
            ax.set_title(f"{m}, {d}\nt = {t_snap:.3f}: largest gap {r['gap'].max():.1f} h", fontsize=9)
    fig.suptitle("hanging block: particle clouds (coloured by initial row)")
    _save(fig, a.out / "hanging_block.png")
    curves = [(r["t"], r["gap"], "-", {"label": f"{m} {d}"}) for (m, d), r in runs.items()]
    plot_curves(a.out / "gaps.png", curves, xlabel="t [s]", ylabel="largest neighbour gap / h",
                title="hanging block: continuity", hlines=[(1.0, {"color": "k", "ls": ":", "label": "one cell"})])


if __name__ == "__main__":
    main()
