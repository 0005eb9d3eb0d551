"""Figures with pyvista (fields and particles) and matplotlib (studies). Imported lazily."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import dolfinx.fem
import numpy as np
import numpy.typing as npt

from fempm.particles.particle_set import Particles

__all__ = [
    "plot_convergence", "plot_curves", "plot_energies", "plot_error_vs_time", "plot_errors", "plot_pareto",
    "plot_particle_frame", "plot_projection", "plot_stability",
]


def _gather(comm, a: npt.NDArray) -> npt.NDArray:
    parts = comm.gather(a, root=0)
    return np.concatenate(parts) if comm.rank == 0 else a


def plot_projection(F: dolfinx.fem.Function, particles: Particles, values: npt.NDArray, path: Path) -> None:
    """Side by side: particles coloured by their values, and the projected field ``F``.

    Under MPI the particles are gathered to rank 0 and each rank's part of the mesh is drawn
    by rank 0 from gathered pieces.
    """
    import dolfinx.plot
    import pyvista

    pyvista.OFF_SCREEN = True
    comm = F.function_space.mesh.comm
    cells, types, x = dolfinx.plot.vtk_mesh(F.function_space)
    pieces = comm.gather((cells, types, x, F.x.array.real.copy()), root=0)
    xp = _gather(comm, np.pad(particles.x, ((0, 0), (0, 3 - particles.gdim))))
    vp = _gather(comm, np.asarray(values))
    if comm.rank != 0:
        return
    grids = []
    for c, t, xx, v in pieces:
        g = pyvista.UnstructuredGrid(c, t, xx)
        g.point_data[F.name] = v
        grids.append(g)
    grid = grids[0] if len(grids) == 1 else pyvista.merge(grids)
    cloud = pyvista.PolyData(xp)
    cloud.point_data["particle value"] = vp
    clim = [float(np.min(vp)), float(np.max(vp))]
    plotter = pyvista.Plotter(shape=(1, 2), window_size=(1400, 650), off_screen=True)
    plotter.subplot(0, 0)
    plotter.add_text("particles", font_size=12)
    plotter.add_mesh(grid, style="wireframe", color="gray", opacity=0.4)
    plotter.add_mesh(cloud, scalars="particle value", point_size=6, render_points_as_spheres=True, clim=clim)
    plotter.view_xy()
    plotter.subplot(0, 1)
    plotter.add_text(F.name, font_size=12)
    plotter.add_mesh(grid, scalars=F.name, show_edges=True, clim=clim)
    plotter.view_xy()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    plotter.screenshot(str(path))
    plotter.close()


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path, rect: tuple[float, float, float, float] | None = None) -> None:
    """Lay out (within ``rect`` of the figure: room left for a figure legend), write, close."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout(rect=rect)
    fig.savefig(path, dpi=130)
    fig.clf()
    _pyplot().close(fig)


def plot_error_vs_time(rows: Sequence[dict], path: Path, *, title: str = "") -> None:
    """Log-log L2 error against wall time: a panel per (field, mass), a line per (mesh, space,
    ppc, domain) series connecting its refinements; the colour is the particle domain, the
    marker the mesh, the line style the space (solid P1, dashed P2, dotted others) and the
    ppc, each told once in a legend of its own."""
    plt = _pyplot()
    from matplotlib.lines import Line2D

    fields = sorted({r["field"] for r in rows})
    masses = sorted({r["mass"] for r in rows})
    domains = sorted({r.get("domain", "point") for r in rows})
    meshes = sorted({r["mesh"] for r in rows})
    styles = sorted({(r["space"], r["ppc"]) for r in rows}, key=str)
    colour = {d: plt.get_cmap("tab10")(k % 10) for k, d in enumerate(domains)}
    marker = {m: "os^Dv<>"[k % 7] for k, m in enumerate(meshes)}
    dashes = ["-", "--", ":", "-."]
    line = {st: dashes[k % len(dashes)] for k, st in enumerate(styles)}
    fig, axes = plt.subplots(len(fields), len(masses), figsize=(4.2 * len(masses) + 2.5, 3.8 * len(fields)),
                             squeeze=False, sharex=True, sharey="row")
    for i, fld in enumerate(fields):
        for j, mass in enumerate(masses):
            ax = axes[i][j]
            series: dict[tuple, list[dict]] = {}
            for r in rows:
                if r["field"] == fld and r["mass"] == mass:
                    series.setdefault((r["mesh"], r["space"], r["ppc"], r.get("domain", "point")), []).append(r)
            for (mesh, space, ppc, domain), rs in sorted(series.items(), key=lambda kv: str(kv[0])):
                rs = sorted(rs, key=lambda r: r["n"])  # connect refinements
                ax.loglog([r["time_s"] for r in rs], [max(r["l2_error"], 1e-17) for r in rs], line[(space, ppc)],
                          marker=marker[mesh], color=colour[domain], ms=4)
            ax.set_title(f"field {fld}, {mass} mass", fontsize=9)
            ax.grid(True, which="both", alpha=0.3)
            if i == len(fields) - 1:
                ax.set_xlabel("wall time of the projection [s]")
            if j == 0:
                ax.set_ylabel("L2 error")
    handles = ([Line2D([], [], color=colour[d], lw=2, label=f"domain {d}") for d in domains]
               + [Line2D([], [], color="k", marker=marker[m], ls="none", label=m) for m in meshes]
               + [Line2D([], [], color="k", ls=line[st], label=f"{st[0]} ppc={st[1]}") for st in styles])
    if title:
        fig.suptitle(title)
    fig.legend(handles=handles, fontsize=7, loc="center right")
    _save(fig, path, rect=(0.0, 0.0, 0.84, 1.0))


def plot_energies(history: Sequence[dict], path: Path, *, title: str = "", extra: dict | None = None) -> None:
    """Kinetic, strain and total energy against time (plus optional extra curves t -> y)."""
    plt = _pyplot()
    t = [r["t"] for r in history]
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for key in ("kinetic", "strain", "total"):
        ax.plot(t, [r[key] for r in history], label=key)
    for label, (tt, yy) in (extra or {}).items():
        ax.plot(tt, yy, "--", label=label)
    ax.set_xlabel("t")
    ax.set_ylabel("energy")
    ax.grid(alpha=0.3)
    ax.legend()
    if title:
        ax.set_title(title)
    _save(fig, path)


def plot_curves(path: Path, curves: Sequence[tuple], *, xlabel: str, ylabel: str, title: str = "",
                hlines: Sequence[tuple[float, dict]] = (), figsize: tuple[float, float] = (7, 4)) -> None:
    """Line plot of ``curves``, each ``(x, y, fmt, kwargs)`` for ``ax.plot(x, y, fmt, **kwargs)``,
    plus horizontal lines ``(y, kwargs)``; with a legend (a demo's result against its reference)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=figsize)
    for x, y, fmt, kw in curves:
        ax.plot(x, y, fmt, **kw)
    for y, kw in hlines:
        ax.axhline(y, **kw)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.legend()
    if title:
        ax.set_title(title)
    _save(fig, path)


def plot_errors(path: Path, series: Sequence[tuple], *, xlabel: str, ylabel: str, title: str = "") -> None:
    """Log-log plot of ``series``, each ``(label, x, error)``: a refinement study's errors."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 5))
    for label, x, err in series:
        ax.loglog(x, err, "o-", label=label)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if series:
        ax.legend(fontsize=7)
    if title:
        ax.set_title(title)
    _save(fig, path)


def plot_particle_frame(x: npt.NDArray, values: npt.NDArray, path: Path, *, title: str = "", label: str = "",
                        bounds: npt.NDArray | None = None) -> None:
    """One PNG frame: particles (n, 3) coloured by ``values`` (2D/3D: x-y view; 1D: x vs value)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 4.6))
    if np.allclose(x[:, 1:], 0.0):
        ax.plot(x[:, 0], values, ".", ms=3)
        ax.set_xlabel("x")
        ax.set_ylabel(label)
    else:
        sc = ax.scatter(x[:, 0], x[:, 1], c=values, s=4, cmap="viridis")
        fig.colorbar(sc, ax=ax, label=label)
        ax.set_aspect("equal")
        if bounds is not None:
            ax.set_xlim(bounds[0, 0], bounds[1, 0])
            ax.set_ylim(bounds[0, 1], bounds[1, 1])
    ax.set_title(title)
    _save(fig, path)


def plot_convergence(rows: Sequence[dict], path: Path, *, title: str = "") -> None:
    """Log-log L2 error against h, one line per configuration of a convergence study: the colour
    is the particle domain, the line the mass (solid: consistent, dashed: lumped), the marker the
    mesh and space; runs that stopped are crosses at their h."""
    plt = _pyplot()
    keys = ("mesh", "degree", "variant", "mass", "domain", "scheme")
    colours = {"point": "tab:red", "ugimp": "tab:olive", "cpgimp": "tab:green", "cpdi1": "tab:blue", "cpdi2": "tab:purple",
               "gimp": "tab:cyan"}
    markers: dict[tuple, str] = {}
    series: dict[tuple, list[dict]] = {}
    for r in rows:
        series.setdefault(tuple(r[k] for k in keys), []).append(r)
    fig, ax = plt.subplots(figsize=(9, 6))
    for key, rs in sorted(series.items(), key=lambda kv: str(kv[0])):
        mesh, degree, variant, mass, domain, scheme = key
        marker = markers.setdefault((mesh, degree, variant), "osD^v<>"[len(markers) % 7])
        ok = sorted((r for r in rs if r["status"] == "ok"), key=lambda r: r["h"])
        label = f"{mesh} P{degree}{'B' if variant == 'bernstein' else ''} {mass} {domain} {scheme}"
        style = dict(color=colours.get(domain, "gray"), marker=marker, ms=4)
        ax.loglog([r["h"] for r in ok], [r["error_l2"] for r in ok], "-" if mass == "consistent" else "--",
                  label=label, **style)
        bad = [r for r in rs if r["status"] != "ok" and np.isfinite(r["h"])]
        if bad:
            ax.loglog([r["h"] for r in bad], [r["error_l2"] if np.isfinite(r["error_l2"]) and r["error_l2"] > 0 else 1.0
                                              for r in bad], "x", color=style["color"], ms=9)
    ax.set_xlabel("h")
    ax.set_ylabel("L2 displacement error (max over time)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6, loc="center left", bbox_to_anchor=(1.0, 0.5))
    if title:
        ax.set_title(f"{title} (x: run stopped)")
    _save(fig, path)


def plot_pareto(rows: Sequence[dict], path: Path, *, title: str = "") -> None:
    """Log-log error against wall time of one problem's runs: colour by mass option, marker
    by particle domain, filled for the Pareto-optimal rows (``pareto``), the front drawn."""
    plt = _pyplot()
    ok = [r for r in rows if np.isfinite(r["error"]) and np.isfinite(r["wall_s"]) and r["error"] > 0]
    fig, ax = plt.subplots(figsize=(8.5, 5.5))
    masses = list(dict.fromkeys(r["mass"] for r in ok))
    colours = plt.get_cmap("tab10")
    markers = {"point": "o", "gimp": "s", "cpgimp": "s", "ugimp": "D", "cpdi1": "^", "cpdi2": "v"}
    for i, m in enumerate(masses):
        for dom in dict.fromkeys(r["domain"] for r in ok if r["mass"] == m):
            rs = [r for r in ok if r["mass"] == m and r["domain"] == dom]
            ax.scatter([r["wall_s"] for r in rs], [r["error"] for r in rs], s=22, marker=markers.get(dom, "x"),
                       facecolors=[colours(i) if r["pareto"] else "none" for r in rs], edgecolors=colours(i),
                       label=f"{m} {dom}")
    front = sorted((r for r in ok if r["pareto"]), key=lambda r: r["wall_s"])
    if front:
        ax.step([r["wall_s"] for r in front], [r["error"] for r in front], "k-", where="post", lw=1.0, label="Pareto front")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time [s]")
    ax.set_ylabel("error")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.0, 0.5))
    if title:
        ax.set_title(title)
    _save(fig, path)


def plot_stability(rows: Sequence[dict], path: Path, *, title: str = "") -> None:
    """The stability catalogue as a matrix: a row per case, a column per option, green stable,
    orange unstable, red aborted, grey refused (the configuration does not take the option: no
    run), the energy ratio written in each cell that ran."""
    plt = _pyplot()
    from matplotlib.colors import ListedColormap

    cases = list(dict.fromkeys(r["case"] for r in rows))
    options = list(dict.fromkeys(r["option"] for r in rows))
    code = {"stable": 0, "unstable": 1, "aborted": 2, "refused": 3}
    grid = np.full((len(cases), len(options)), np.nan)
    for r in rows:
        grid[cases.index(r["case"]), options.index(r["option"])] = code[r["outcome"]]
    fig, ax = plt.subplots(figsize=(1.0 + 0.55 * len(options), 1.5 + 0.4 * len(cases)))
    ax.imshow(np.ma.masked_invalid(grid), cmap=ListedColormap(["#4caf50", "#ff9800", "#e53935", "#bdbdbd"]), vmin=0,
              vmax=3, aspect="auto")
    for r in rows:
        ratio = r["energy_ratio"]
        text = "n/a" if r["outcome"] == "refused" else f"{ratio:.2g}" if np.isfinite(ratio) else "-"
        ax.text(options.index(r["option"]), cases.index(r["case"]), text, ha="center", va="center", fontsize=6)
    ax.set_xticks(range(len(options)), options, rotation=90, fontsize=6)
    ax.set_yticks(range(len(cases)), cases, fontsize=7)
    ax.set_title(title or "stability: green stable, orange unstable (energy), red aborted, grey refused (n/a); "
                 "E/E0 in the cells", fontsize=8)
    _save(fig, path)
