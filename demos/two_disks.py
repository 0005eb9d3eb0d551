r"""# Two colliding elastic disks (Sulsky, Chen and Schreyer 1994)

Two disks of radius 0.2 ($E = 1000$, $\nu = 0.3$, $\rho = 1000$, plane strain) approach each
other at $\pm(0.1, 0.1)$ on the unit square, collide through the single-valued grid velocity
(no contact algorithm) and rebound. Without boundary contact the total linear momentum is
conserved to round-off; we plot kinetic, strain and total energy against time.

The default runs on the unstructured triangle mesh `meshes/unit_square_tri.msh` (h = 0.05);
`--mesh structured` uses 20 x 20 quadrilaterals. Outputs: `energies.csv`, particle frames
(`particles.pvd` for ParaView and pyvista, `frames/*.png`), the grid velocity (`grid_velocity.pvd`), `energies.png`,
`disks.png` and `summary.json`.

Run: `.venv/bin/python demos/two_disks.py [--mesh structured] [--mass consistent] [--out output/disks]`
"""

from __future__ import annotations

import argparse
from pathlib import Path

import fempm  # noqa: F401
import numpy as np
from mpi4py import MPI

from fempm.scene import run
from fempm.scenes import two_disks


#: the small run its page in the docs shows, executed when the site is built (docs/demo_runs.py)
DOCS_RUN = ["--mesh", "structured", "--t-end", "0.5"]


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description="two colliding disks")
    ap.add_argument("--mesh", default="unstructured", choices=["structured", "unstructured"])
    ap.add_argument("--cells", type=int, default=20)
    ap.add_argument("--mass", default="lumped", choices=["lumped", "consistent"])
    ap.add_argument("--scheme", default="MUSL")
    ap.add_argument("--t-end", type=float, default=3.5)
    ap.add_argument("--out", type=Path, default=Path("output/disks"))
    ap.add_argument("--no-plot", action="store_true")
    a = ap.parse_args(argv)
    comm = MPI.COMM_WORLD
    scene = two_disks(mesh=a.mesh, cells=a.cells, mass=a.mass, scheme=a.scheme, t_end=a.t_end)
    res = run(scene, a.out, progress=comm.rank == 0, png=not a.no_plot)
    h = res["history"]
    p0 = np.array([h[0]["momentum_x"], h[0]["momentum_y"]])
    drift = max(np.abs(np.array([r["momentum_x"], r["momentum_y"]]) - p0).max() for r in h)
    ke = np.array([r["kinetic"] for r in h])
    t = np.array([r["t"] for r in h])
    # the disks rebound: after the collision they move apart again (lower disk centre of mass
    # velocity changes sign along the diagonal)
    part = scene.particles
    lower = (part.x.sum(axis=1) < 1.0).astype(float)
    m_low = comm.allreduce(part.mass @ lower)
    v_low = comm.allreduce((part.mass * lower) @ part.fields["v"]) / m_low
    out = {
        "particles": res["particles"],
        "momentum_drift": float(drift),
        "kinetic_initial": float(ke[0]),
        "kinetic_min": float(ke.min()),
        "t_kinetic_min": float(t[ke.argmin()]),
        "kinetic_final": float(ke[-1]),
        "total_final": float(h[-1]["total"]),
        "lower_disk_velocity_final": v_low.tolist(),
        "particle_steps_per_s": res["particle_steps_per_s"],
        "steps": res["steps"],
    }
    if comm.rank == 0:
        print(f"two disks ({a.mesh}, {a.mass}): {res['particles']} particles, momentum drift {drift:.1e}, "
              f"kinetic {ke[0]:.4f} -> min {ke.min():.4f} at t = {out['t_kinetic_min']:.3f} -> {ke[-1]:.4f}, "
              f"lower disk velocity {np.round(v_low, 4).tolist()}")
        if not a.no_plot:
            from fempm.io.plot import plot_energies

            plot_energies(h, a.out / "energies.png", title=f"two disks, {a.mesh} mesh, {a.scheme}, {a.mass} mass")
    if not a.no_plot:
        _plot_particles(scene, a.out / "disks.png")
    return out


def _plot_particles(scene, path: Path) -> None:
    """Final particle positions coloured by von Mises stress."""
    comm = MPI.COMM_WORLD
    p = scene.particles
    s = p.fields["sigma"]
    vm = np.sqrt(np.maximum(s[:, 0, 0] ** 2 - s[:, 0, 0] * s[:, 1, 1] + s[:, 1, 1] ** 2 + 3 * s[:, 0, 1] ** 2, 0.0))
    xs, vs = comm.gather(p.x, root=0), comm.gather(vm, root=0)
    if comm.rank == 0:
        from fempm.io.plot import plot_particle_frame

        plot_particle_frame(np.concatenate(xs), np.concatenate(vs), path, title=f"two disks at t = {scene.t_end:g}",
                            label="von Mises stress", bounds=np.array([[0.0, 0.0], [1.0, 1.0]]))


if __name__ == "__main__":
    main()
