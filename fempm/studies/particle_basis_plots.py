"""Figures of the particle-basis study (:mod:`fempm.studies.particle_basis`), drawn as in
docs/particle_basis.md: top hat, particle basis function with its nodal values, the other
particles' basis functions, and the grid fields of constant and linear particle data."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fempm.io.plot import _pyplot, _save
from fempm.studies.particle_basis_bodies import (
    DENSITIES,
    DOMAINS,
    OPTIONS,
    line_body,
    quad_body,
    tri_body,
)

__all__ = ["MOTIONS", "figures_1d", "figures_2d"]

MOTIONS = {
    "translation": [dict(shift=0.0), dict(shift=0.25), dict(shift=0.5)],
    "stretching": [dict(A=[[1.0]]), dict(A=[[1.25]]), dict(A=[[1.5]])],
}


def _label(state: dict) -> str:
    if "shift" in state:
        return f"shift {state['shift']:g} h"
    return f"stretch {np.ravel(state['A'])[0]:g}"


def _in_cells(state: dict, density: float) -> dict:
    """A state's keyword arguments for :func:`line_body`, the shift given in cell sizes (the
    grid of the 1/2-per-cell case is twice as fine)."""
    kw = dict(state)
    if "shift" in kw:
        kw["shift"] = kw["shift"] * (1.0 if density >= 1 else 0.5)
    return kw


def _chosen(b) -> int:
    """The particle nearest to a point just right of the body's centre."""
    c = 0.5 * (b.lo + b.hi) + 0.3 * b.h
    return int(np.argmin(np.linalg.norm(b.x - c, axis=1)))


def figures_1d(out: Path, domain: str = "cpdi1") -> list[Path]:
    plt = _pyplot()
    paths = []
    for option in OPTIONS:
        for motion, states in MOTIONS.items():
            fig, axes = plt.subplots(len(states) + 1, len(DENSITIES), figsize=(4.0 * len(DENSITIES), 2.3 * (len(states) + 1)),
                                     sharey="row", squeeze=False)
            for j, dens in enumerate(DENSITIES):
                bodies = [line_body(dens, DOMAINS[domain], **_in_cells(st, dens)) for st in states]
                for i, (st, b) in enumerate(zip(states, bodies)):
                    P = b.psi(option)
                    order = np.argsort(b.xd[:, 0])
                    xn = b.xd[order, 0]
                    k = _chosen(b)
                    ax = axes[i, j]
                    ell = b.spacing / 2 * (np.ravel(st.get("A", [[1.0]]))[0])
                    xp = b.x[k, 0]
                    ax.fill_between([xp - ell, xp + ell], 0, 1, color="0.85", lw=0, label="top hat")
                    ax.plot(xn, np.delete(P[order], k, axis=1), lw=0.7, alpha=0.8)  # the other particles' Phi
                    ax.fill_between(xn, 0, P[order, k], color="0.3", alpha=0.8, lw=0, label="Phi_p")
                    ax.plot(xn, P[order, k], "o", color="k", ms=2.5)
                    ax.plot(b.x[:, 0], np.zeros(len(b.x)), "|", color="C3", ms=6)
                    for xv in xn:
                        ax.axvline(xv, color="0.9", lw=0.5, zorder=0)
                    ax.set_xlim(1.5, 8.5)
                    ax.set_ylim(-0.45 if option == "consistent" else -0.05, 1.1)
                    ax.set_title(f"{dens:g} per cell, {_label(st)}", fontsize=9)
                # last row: constant and linear data at the middle state
                b = bodies[1]
                P = b.psi(option)
                order = np.argsort(b.xd[:, 0])
                lin = (b.x[:, 0] - b.lo[0]) / (b.hi[0] - b.lo[0])
                ax = axes[-1, j]
                ax.plot(b.xd[order, 0], P[order] @ np.ones(len(b.x)), "-", color="C0", label="constant data")
                ax.plot(b.xd[order, 0], P[order] @ lin, "-", color="C1", label="linear data")
                ax.plot(b.x[:, 0], lin, ".", color="C1", ms=4)
                ax.plot(b.x[:, 0], np.ones(len(b.x)), ".", color="C0", ms=4)
                ax.set_xlim(1.5, 8.5)
                ax.set_ylim(-0.3, 1.3)
                ax.set_title(f"grid fields, {_label(states[1])}", fontsize=9)
            axes[-1, 0].legend(fontsize=7, loc="upper left")
            axes[0, 0].legend(fontsize=7, loc="upper left")
            fig.suptitle(f"1D particle basis functions, {option} psi ({'option 1' if option == 'lumped' else 'option 2'}), "
                         f"{domain} domains, {motion}")
            fig.tight_layout()
            paths.append(_save(fig, out / f"particle_basis_1d_{option}_{motion}.png"))
    return paths


def _triangles(b):
    """Plot triangles over the P1 dofs (quadrilaterals split in two)."""
    cells = np.asarray(b.V.dofmap.list)
    if cells.shape[1] == 4:  # DOLFINx quadrilateral vertex order (0,0), (1,0), (0,1), (1,1)
        return np.vstack([cells[:, [0, 1, 3]], cells[:, [0, 3, 2]]])
    return cells


def figures_2d(out: Path, domain: str = "cpdi1") -> list[Path]:
    plt = _pyplot()
    import matplotlib.tri as mtri

    paths = []
    states = [("reference", {}), ("translated (0.3 h, 0.2 h)", dict(shift=[0.3, 0.2])),
              ("stretched 1.4", dict(A=[[1.4, 0.0], [0.0, 1.4]]))]
    for option in OPTIONS:
        fig, axes = plt.subplots(len(states) + 1, len(DENSITIES), figsize=(3.6 * len(DENSITIES), 3.4 * (len(states) + 1)),
                                 squeeze=False)
        for j, dens in enumerate(DENSITIES):
            rows = [(name, quad_body(dens, DOMAINS[domain], **kw)) for name, kw in states]
            if j == 0:
                rows.append(("unstructured triangles", tri_body(DOMAINS[domain])))
            for i, (name, b) in enumerate(rows):
                ax = axes[i, j]
                P = b.psi(option)
                k = _chosen(b)
                tri = mtri.Triangulation(b.xd[:, 0], b.xd[:, 1], _triangles(b))
                vmax = np.abs(P[:, k]).max()
                im = ax.tripcolor(tri, P[:, k], shading="gouraud", cmap="RdBu_r", vmin=-vmax, vmax=vmax)
                ax.triplot(tri, color="0.85", lw=0.3)
                ax.plot(b.x[:, 0], b.x[:, 1], ".", color="0.3", ms=1.5)
                R = b.particles.fields["F"][0] * (b.spacing / 2)
                corners = b.x[k] + np.array([[-1, -1], [1, -1], [1, 1], [-1, 1], [-1, -1]]) @ R.T
                ax.plot(corners[:, 0], corners[:, 1], "-", color="k", lw=1.0)
                ax.set_aspect("equal")
                ax.set_xlim(0.5, 7.5)
                ax.set_ylim(0.5, 7.5)
                ax.set_xticks([])
                ax.set_yticks([])
                ax.set_title(f"{name}, {dens:g}/cell/dir\nmin {P[:, k].min():.2f}, max {P[:, k].max():.2f}"
                             if "triangles" not in name else f"{name}, 2/cell/dir\nmin {P[:, k].min():.2f}, max {P[:, k].max():.2f}",
                             fontsize=8)
                fig.colorbar(im, ax=ax, shrink=0.7)
        for j in range(1, len(DENSITIES)):
            axes[-1, j].axis("off")
        fig.suptitle(f"2D particle basis function of one particle, {option} psi, {domain} domains (box outlined)")
        fig.tight_layout()
        paths.append(_save(fig, out / f"particle_basis_2d_{option}.png"))
    return paths
