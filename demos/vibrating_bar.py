r"""# Vibrating bar (1D): MPM against the exact solution

A bar of length $L = 25$, $E = 100$, $\rho = 1$, fixed at $x = 0$ and free at $x = L$, starts in
its first mode, $v(x, 0) = v_0 \sin(\beta x)$, $\beta = \pi / (2L)$. With $\sigma = E(F - 1)$ the
Lagrangian equation is linear, and the centre-of-mass velocity is exactly

$$ v_{cm}(t) = \frac{v_0}{\beta L} \cos(\omega t), \qquad \omega = \beta \sqrt{E/\rho} $$

(period 10), with total energy $\rho v_0^2 L / 4$. We run USL with FLIP ($\alpha = 1$), 2 particles
per cell, lumped and consistent mass, and report the largest $|v_{cm} - v_{cm}^{exact}|$ relative
to the amplitude up to $t = 40$, and the total-energy error.

Run: `.venv/bin/python demos/vibrating_bar.py [--cells 16] [--mass consistent] [--out output/bar]`
"""

from __future__ import annotations

import argparse
from pathlib import Path

import fempm  # noqa: F401
import numpy as np
from mpi4py import MPI

from fempm.scene import run
from fempm.scenes import vibrating_bar


#: the small run its page in the docs shows, executed when the site is built (docs/demo_runs.py)
DOCS_RUN = ["--cells", "16"]


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description="vibrating bar")
    ap.add_argument("--cells", type=int, default=16)
    ap.add_argument("--mass", default="consistent", choices=["lumped", "consistent"])
    ap.add_argument("--scheme", default="USL")
    ap.add_argument("--flip", type=float, default=1.0)
    ap.add_argument("--cfl", type=float, default=0.5)
    ap.add_argument("--t-end", type=float, default=40.0)
    ap.add_argument("--dim", type=int, default=1, choices=[1, 2], help="2: a strip of quadrilaterals")
    ap.add_argument("--lumped-forces", action="store_true", help="consistent velocity map, lumped forces")
    ap.add_argument("--out", type=Path, default=Path("output/bar"))
    ap.add_argument("--no-plot", action="store_true")
    a = ap.parse_args(argv)
    scene = vibrating_bar(cells=a.cells, mass=a.mass, scheme=a.scheme, flip=a.flip, cfl=a.cfl, t_end=a.t_end,
                          dim=a.dim, lumped_forces=a.lumped_forces)
    P = scene.params
    M = MPI.COMM_WORLD.allreduce(scene.particles.mass.sum())
    amp = P["v0"] / (P["beta"] * P["L"])
    res = run(scene, a.out, progress=False)
    h = res["history"]
    t = np.array([r["t"] for r in h])
    vcm = np.array([r["momentum_x"] for r in h]) / M
    exact = amp * np.cos(P["omega"] * t)
    E_exact = P["rho"] * P["v0"] ** 2 * P["L"] / 4 * (P["L"] / a.cells) ** (a.dim - 1)  # x strip height
    out = {
        "vcm_error": float(np.max(np.abs(vcm - exact)) / amp),
        "energy_error": float(abs(h[-1]["total"] - E_exact) / E_exact),
        "steps": res["steps"],
        "particle_steps_per_s": res["particle_steps_per_s"],
        "t": t.tolist(),
        "vcm": vcm.tolist(),
    }
    if MPI.COMM_WORLD.rank == 0:
        print(f"bar ({a.dim}D), {a.cells} cells, {a.scheme}, flip={a.flip}, {a.mass}: max |v_cm error| / amplitude = "
              f"{out['vcm_error']:.4f}, energy error = {out['energy_error']:.2e}, {res['steps']} steps")
        if not a.no_plot:
            from fempm.io.plot import plot_curves

            plot_curves(a.out / "vcm.png", [(t, vcm, "-", {"label": "fempm"}), (t, exact, "--", {"label": "exact"})],
                        xlabel="t", ylabel="centre-of-mass velocity",
                        title=f"vibrating bar: {a.cells} cells, {a.scheme}-FLIP, {a.mass} mass")
    return out


if __name__ == "__main__":
    main()
