r"""# Cantilever under self-weight: MPM against Euler-Bernoulli

A beam $L = 0.7$ m long and $H = 0.047$ m thick ($\rho = 1000$, $E = 6\cdot10^7$, $\nu = 0$) is
clamped at $x = 0$ and gravity $g = 10$ is switched on at $t = 0$. Euler-Bernoulli gives the
static tip deflection

$$ \delta = \frac{q L^4}{8 E I}, \qquad q = \rho g H, \quad I = H^3 / 12
   \quad\Rightarrow\quad \delta = 0.02717 \text{ m}, $$

with the deflection line $w(x) = q x^2 (6L^2 - 4Lx + x^2) / (24 EI)$. We follow the particles
seeded in the last cell column and compare their mean deflection with $w$ at their mean
position (a column half a cell from the end sits about $\tfrac{2}{3} h / L$ below $\delta$).
With no damping, the tip oscillates between $0$ and about $2\delta$ with the first-mode
period $T = 2\pi / (1.8751^2 \sqrt{EI / (\rho H L^4)}) = 0.2635$ s. The check is the
time-averaged tip deflection over whole periods.

The grid is Q1 on quadrilaterals, 4 cells through the thickness, 2x2 particles per cell,
lumped mass, MUSL. The clamp is the grid condition $v = 0$ on the mesh's left edge.
The PIC/FLIP blend is $\alpha = 0.95$: with pure FLIP ($\alpha = 1$) and the standard
(point) basis, the free-end corner particles develop a growing cell-crossing oscillation once
the tip has moved about three cells (t = 0.09 s, at CFL 0.4 and 0.05 alike, so it is not a
time-step instability); 5 % PIC damps it while leaving the bending mode nearly undamped
(pure PIC, $\alpha = 0$, damps the beam to a slow creep instead).

Run: `.venv/bin/python demos/cantilever.py [--cells 4] [--periods 2] [--out output/cantilever]`
"""

from __future__ import annotations

import argparse
from pathlib import Path

import fempm  # noqa: F401
import numpy as np

from fempm.scene import run, run_stats
from fempm.scenes import cantilever, cantilever_reference, cantilever_tip


#: the small run its page in the docs shows, executed when the site is built (docs/demo_runs.py)
DOCS_RUN = ["--cells", "4", "--periods", "1"]


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description="cantilever under self-weight")
    ap.add_argument("--cells", type=int, default=4, help="cells through the thickness")
    ap.add_argument("--periods", type=float, default=2.0, help="run time in first-mode periods")
    ap.add_argument("--flip", type=float, default=0.95)
    ap.add_argument("--scheme", default="MUSL")
    ap.add_argument("--mass", default="lumped", choices=["lumped", "consistent"])
    ap.add_argument("--material", default="neo-hookean", choices=["neo-hookean", "linear"])
    ap.add_argument("--domain", default="point", choices=["point", "gimp", "cpdi1", "cpdi2"])
    ap.add_argument("--cfl", type=float, default=0.4)
    ap.add_argument("--out", type=Path, default=Path("output/cantilever"))
    ap.add_argument("--no-plot", action="store_true")
    a = ap.parse_args(argv)
    period = cantilever_reference()["period"]
    scene = cantilever(cells=a.cells, flip=a.flip, scheme=a.scheme, mass=a.mass, cfl=a.cfl, material=a.material, domain=a.domain,
                       t_end=a.periods * period, frames=10)
    P = scene.params
    p = scene.particles
    comm = p.comm

    # The tip: the particles seeded in the last cell column, averaged over ranks.
    x_tip, _ = cantilever_tip(p, P)
    q, EI, L = P["rho"] * P["g"] * P["H"], P["E"] * P["H"] ** 3 / 12, P["L"]
    w_ref = q * x_tip**2 * (6 * L**2 - 4 * L * x_tip + x_tip**2) / (24 * EI)  # Euler-Bernoulli w(x_tip)

    times, tips = [0.0], [0.0]

    def record(solver):
        times.append(solver.t)
        tips.append(cantilever_tip(p, P)[1])

    res = run(scene, a.out, progress=False, callback=record)
    t, d = np.array(times), np.array(tips)
    whole = max(int(np.floor(t[-1] / period * (1 + 1e-9))), 1) * period
    sel = t <= whole * (1 + 1e-9)
    mean = np.trapezoid(d[sel], t[sel]) / t[sel][-1]
    out = {
        "tip_mean": float(mean),
        "tip_reference": P["tip_deflection"],
        "x_tip": float(x_tip),
        "reference_at_x_tip": float(w_ref),
        "tip_error": float(mean / w_ref - 1),
        "tip_max": float(d.max()),
        "averaged_over": float(t[sel][-1]),
        "period": period,
        **run_stats(res),
    }
    if comm.rank == 0:
        np.savetxt(a.out / "tip.csv", np.c_[t, d], delimiter=",", header="t,tip_deflection", comments="")
        print(f"cantilever, {a.cells} cells thick, {a.scheme}, flip={a.flip}, {a.mass}: time-averaged deflection at "
              f"x = {x_tip:.4f} m: {mean:.5f} m over {out['averaged_over']:.3f} s vs Euler-Bernoulli {w_ref:.5f} m "
              f"({out['tip_error']:+.2%}; q L^4 / 8EI = {P['tip_deflection']:.5f} m); largest {d.max():.5f} m; "
              f"{res['steps']} steps")
        if not a.no_plot:
            from fempm.io.plot import plot_curves

            plot_curves(a.out / "tip.png", [(t, d, "-", {"label": "fempm tip deflection"})],
                        hlines=[(w_ref, {"color": "k", "ls": "--", "label": f"Euler-Bernoulli w(x = {x_tip:.4f})"}),
                                (mean, {"color": "C1", "ls": ":", "label": f"time average ({out['tip_error']:+.1%})"})],
                        xlabel="t [s]", ylabel="tip deflection [m]",
                        title=f"cantilever: {a.cells} cells thick, {a.scheme}, flip {a.flip}, {a.mass} mass")
    return out


if __name__ == "__main__":
    main()
