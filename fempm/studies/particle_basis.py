r"""Particle-basis study: the implied particle basis functions :math:`\Phi_p` of option 1
(lumped) and option 2 (consistent), their figures and a table of their properties.

Run ``python -m fempm study particle-basis [--out DIR]`` (one rank). It writes

* ``particle_basis_1d_<option>_<motion>.png``: 1D bodies of 4, 2, 1 and 1/2 particles per
  cell (the 1/2 case on a grid twice as fine, particles of the 1-per-cell size) with CPDI
  domains, under pure translation and under uniform stretching; each panel shows the chosen
  particle's top hat (light), its :math:`\Phi_p` (dark, nodal values as dots) and the other
  particles' basis functions (lines); the last row the grid fields of constant and linear
  particle data (as frames instead of animations);
* ``particle_basis_2d_<option>.png``: :math:`\Phi_p` of one particle on a quadrilateral grid
  (4, 2, 1 and 1/2 particles per cell and direction; reference, translated and stretched
  bodies) and on an unstructured triangle mesh;
* ``properties.md`` / ``properties.csv``: the properties (i)-(xiv) of docs/particle_basis_properties.md
  measured for each option and domain (point, GIMP, CPDI1, CPDI2 lattice cells) on a 1D body (2 particles per
  cell) and on a 2D body on unstructured triangles (2 x 2 per cell), and the claims
  on support and linear fields.

Everything is measured with dense operators (:func:`fempm.transfer.particle_basis.dense_operator`),
and property (xiv) checks them against the PETSc projection
(:func:`fempm.transfer.particle_basis.particle_basis_functions`).
"""

from __future__ import annotations

import csv
from collections.abc import Callable
from pathlib import Path

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI

from fempm.studies.harness import Provenance
from fempm.studies.particle_basis_bodies import (
    ALG_TOL,
    DENSITIES,
    DOMAINS,
    OPTION_NAMES,
    OPTIONS,
    TOL,
    Body,
    line_body,
    tri_body,
)
from fempm.studies.particle_basis_plots import figures_1d, figures_2d
from fempm.transfer.particle_basis import (
    dense_operator,
    particle_basis_functions,
)

__all__ = ["BASE_SHIFT", "PROPERTIES", "linear_fields", "measure", "property_table", "run", "write_markdown"]

# -- properties ---------------------------------------------------------------------------------

def _interior_particles(b: Body, margin: float) -> np.ndarray:
    return np.flatnonzero(np.all((b.x > b.lo + margin) & (b.x < b.hi - margin), axis=1))


def _interior_dofs(b: Body, margin: float) -> np.ndarray:
    return np.flatnonzero(np.all((b.xd > b.lo + margin) & (b.xd < b.hi - margin), axis=1))


def _integrals(b: Body) -> np.ndarray:
    v = ufl.TestFunction(b.V)
    return dolfinx.fem.assemble_vector(dolfinx.fem.form(v * ufl.dx)).array


def measure(make: Callable, option: str, domain_name: str, dim: int) -> dict[str, tuple[bool, str]]:
    """Properties (i)-(xiv) and the claims for one option and domain. ``make(**kw)``
    builds the body (``shift``, ``A``, ``grid_moves``). Returns {key: (holds, number text)}."""
    dom = DOMAINS[domain_name]
    b = make(dom)
    P = b.psi(option)  # (ndofs, n)
    h = b.h
    inner = _interior_particles(b, 1.5 * h)
    touched = np.abs(b.S).sum(axis=0) > 0
    idofs = np.intersect1d(_interior_dofs(b, 1.5 * h), np.flatnonzero(touched))
    r: dict[str, tuple[bool, str]] = {}
    # (i) not an interpolation
    Pq = b.at(b.x) @ P  # Phi_p(x_q), (q, p)
    dev = np.abs(Pq[np.ix_(inner, inner)] - np.eye(len(b.x))[np.ix_(inner, inner)]).max()
    r["i"] = (dev > 1e-3, f"max dev. {dev:.3g}")
    # (ii) partition of unity on the dofs the particles touch
    pu = np.abs(P.sum(axis=1) - 1)[touched].max()
    r["ii"] = (pu < ALG_TOL, f"{pu:.2g}")
    # (iii) linear completeness: interior dofs and all touched dofs
    lc = np.abs(P @ b.x - b.xd)
    r["iii"] = (lc[idofs].max() < ALG_TOL, f"interior {lc[idofs].max():.2g}, edge {lc[touched].max():.2g}")
    # (iv) piecewise differentiable
    r["iv"] = (True, "by construction (P1 Function)")
    # (viii) positivity
    lo_, hi_ = P.min(), P.max()
    r["viii"] = (bool(lo_ >= -TOL and hi_ <= 1 + TOL), f"min {lo_:.3g}, max {hi_:.3g}")
    # (vii) particles whose domains lie in one cell share their influence domain
    r["vii"] = _same_cell_supports(b, dom, P)
    # (x) grid and particles translated together
    s = 0.37 * h * np.ones(dim)
    bt = make(dom, shift=s, grid_moves=True)
    gx = np.abs(bt.psi(option) - P).max()
    r["x"] = (gx < ALG_TOL, f"{gx:.2g}")
    # (xi) particles translated relative to the grid, and the rate dv_ip/dt = G_i . xdot_p
    r["xi"] = _moving_relative(make, dom, option, b, P, idofs, inner, s)
    # (xii) integral of Phi_p constant under translation relative to the grid
    ints = []
    for t in np.linspace(0.0, h, 7, endpoint=False):
        bt = make(dom, shift=t * np.ones(dim) * np.array([1.0, 0.61][:dim]))
        ints.append(_integrals(bt) @ bt.psi(option))
    ints = np.array(ints)
    drift = (ints.max(axis=0) - ints.min(axis=0)) / b.particles.volume[0]
    r["xii"] = (drift[inner].max() < 1e-10, f"interior {drift[inner].max():.2g}, all {drift.max():.2g}")
    # (xiii) homogeneous deformation: with the grid (invariant) and without (not)
    A = np.array([[1.3]]) if dim == 1 else np.array([[1.3, 0.2], [0.0, 0.8]])
    bd = make(dom, A=A, grid_moves=True)
    lag = np.abs(bd.psi(option) - P).max()
    bf = make(dom, A=A)
    pts = b.xd[idofs]
    c = 0.5 * (b.xd.min(axis=0) + b.xd.max(axis=0))
    not_lag = np.abs(bf.at(c + (pts - c) @ A.T) @ bf.psi(option) - b.at(pts) @ P)[:, inner].max()
    r["xiii"] = (lag < ALG_TOL, f"with the grid {lag:.2g}; grid fixed {not_lag:.3g}")
    # (xiv) Phi_p is the projection of f_q = delta_pq (PETSc path against the dense formula)
    r["xiv"] = _projection_of_delta(b, dom, option, P, inner)
    # support of an interior particle's basis
    k = inner[len(inner) // 2]
    supp = np.mean(np.abs(P[touched, k]) > 1e-10 * np.abs(P[:, k]).max())
    r["support"] = (supp < 0.5, f"nonzero on {100 * supp:.0f} % of dofs")
    if dim == 1:
        r.update(_one_d(b, P, inner))
    else:
        for key in ("v", "vi", "ix"):
            r[key] = (None, "1D only")
    return r


def _moving_relative(make: Callable, dom, option: str, b: Body, P, idofs, inner, s) -> tuple[bool, str]:
    r"""(xi): translated by ``s`` relative to the grid the basis changes, at the rate
    :math:`\dot v_{ip} = G_i \cdot \dot x_p` (central differences against the gradients)."""
    dim = len(s)
    h = b.h
    bs = make(dom, shift=s)
    pts = b.xd[idofs]
    change = np.abs(bs.at(pts + s) @ bs.psi(option) - b.at(pts) @ P)[:, inner].max()
    eps = 1e-6 * h
    e = np.zeros(dim)
    e[0] = 1.0
    Sp, Sm = make(dom, shift=0.2 * h * e + eps * e).S, make(dom, shift=0.2 * h * e - eps * e).S
    b2 = make(dom, shift=0.2 * h * e)
    _, G = dense_operator(b2.V, b2.particles, dom, gradients=True)
    rate = np.abs((Sp - Sm) / (2 * eps) - G[:, :, 0]).max() / np.abs(G[:, :, 0]).max()
    return (change > 1e-6 and rate < 1e-5, f"change {change:.3g}; rate error {rate:.2g}")


def _projection_of_delta(b: Body, dom, option: str, P, inner) -> tuple[bool, str]:
    """(xiv): :math:`\\Phi_p` is the projection of :math:`f_q = \\delta_{pq}` (the PETSc path of
    :func:`fempm.transfer.particle_basis.particle_basis_functions` against the dense formula)."""
    pick = inner[:: max(1, len(inner) // 3)][:3]
    ids = np.sort(b.particles.ids)[pick]
    try:
        funcs = particle_basis_functions(b.V, b.particles, ids, option="consistent" if option == "partial" else option,
                                         domain=dom, lump_below=0.1 if option == "partial" else 0.0)
        err = max(np.abs(u.x.array - P[:, k]).max() for u, k in zip(funcs, pick))
        return (err < ALG_TOL, f"{err:.2g}")
    except Exception as ex:  # e.g. a singular consistent mass matrix
        return (False, f"{type(ex).__name__}")


def _same_cell_supports(b: Body, dom, P) -> tuple[bool, str]:
    smp = dom.samples(b.particles)
    n, q, d = smp.x.shape
    cells, _ = b.particles.sample_locator.relocate(smp.x.reshape(n * q, d), np.repeat(b.particles.cells, q))
    cells = cells.reshape(n, q)
    order = np.argsort(b.particles.ids)
    cells = cells[order]
    one = np.all(cells == cells[:, :1], axis=1)
    supp = np.abs(P) > 1e-12 * np.abs(P).max(axis=0)
    same = total = 0
    for c in np.unique(cells[one, 0]):
        members = np.flatnonzero(one & (cells[:, 0] == c))
        for a, bb in zip(members[:-1], members[1:]):
            total += 1
            same += np.array_equal(supp[:, a], supp[:, bb])
    if total == 0:
        return (None, "no two domains in one cell")
    return (same == total, f"{same}/{total} pairs identical")


def _one_d(b: Body, P, inner) -> dict:
    """(v) symmetry, (vi) shape vs position, (ix) unimodality, on a 1D body."""
    h = b.h
    s = np.linspace(0.01, 2.5, 120) * h
    asym = []
    for p in inner:
        xp = b.x[p, 0]
        fp = b.at((xp + s)[:, None]) @ P[:, p]
        fm = b.at((xp - s)[:, None]) @ P[:, p]
        asym.append(np.abs(fp - fm).max() / P[:, p].max())
    asym = np.array(asym)
    nsym = int(np.sum(asym < 1e-10))
    r = {"v": (nsym == 0, f"asymmetry {asym.min():.2g} to {asym.max():.2g}; {nsym}/{len(asym)} symmetric")}
    per = int(round(h / b.spacing)) if b.spacing <= h else 1
    xs = np.linspace(-2.5, 2.5, 200) * h
    diffs_adj, diffs_cell = [], []
    for p in inner:
        for q, bucket in ((p + 1, diffs_adj), (p + per, diffs_cell)):
            if q in inner and q != p:
                dq = b.x[q, 0] - b.x[p, 0]
                fp = b.at((b.x[p, 0] + xs)[:, None]) @ P[:, p]
                fq = b.at((b.x[p, 0] + dq + xs)[:, None]) @ P[:, q]
                bucket.append(np.abs(fp - fq).max())
    adj = min(diffs_adj) if diffs_adj else np.nan
    cell = max(diffs_cell) if diffs_cell else np.nan
    r["vi"] = (adj > 1e-10, f"neighbours differ by >= {adj:.3g}; one cell apart by <= {cell:.2g}")
    order = np.argsort(b.xd[:, 0])
    bad = 0
    for p in inner:
        v = P[order, p]
        dv = np.diff(v)
        sgn = np.sign(np.where(np.abs(dv) > 1e-12, dv, 0.0))
        sgn = sgn[sgn != 0]
        bad += bool(np.any(np.diff(sgn) > 0))  # a rise after a fall
    r["ix"] = (bad == 0, f"{bad}/{len(inner)} not unimodal")
    return r


PROPERTIES = [
    ("i", "Phi_p(x_q) != delta_pq (not an interpolation)"),
    ("ii", "partition of unity sum_p Phi_p = 1"),
    ("iii", "linear completeness sum_p x_p Phi_p = x"),
    ("iv", "piecewise differentiable"),
    ("v", "not symmetric about the particle, even for uniform spacing"),
    ("vi", "equal domains at different grid positions give different shapes"),
    ("vii", "domains in one shared element give equal influence domains"),
    ("viii", "positivity 0 <= Phi_p <= 1"),
    ("ix", "monotone away from its maximum (unimodal)"),
    ("x", "Galilean invariant when grid and particles translate together"),
    ("xi", "not invariant when particles translate relative to the grid; dv_ip/dt = G_i . xdot_p"),
    ("xii", "integral of Phi_p constant under translation"),
    ("xiii", "Lagrangian invariant under homogeneous deformation with the grid (not without)"),
    ("xiv", "Phi_p = projection of f_q = delta_pq"),
    ("support", "compact support (option 2 is not)"),
]


#: the bodies of the table sit at a generic offset from the grid (no accidental symmetry)
BASE_SHIFT = np.array([0.13, 0.07])


def _table_line(dom, **kw) -> Body:
    return line_body(2, dom, length=16.0, offset=BASE_SHIFT[:1], **kw)


def _table_tri(dom, **kw) -> Body:
    return tri_body(dom, length=10.0, offset=BASE_SHIFT, **kw)


def property_table(out: Path) -> list[dict]:
    rows = []
    makers = {"1D": _table_line, "2D tri": _table_tri}
    for option in OPTIONS:
        for dname in DOMAINS:
            res = {mk: measure(f, option, dname, 1 if mk == "1D" else 2) for mk, f in makers.items()}
            for key, text in PROPERTIES:
                row = {"property": key, "claim": text, "option": option, "domain": dname}
                for mk in makers:
                    holds, num = res[mk][key]
                    row[f"{mk} holds"] = {True: "yes", False: "no", None: "-"}[holds]
                    row[f"{mk} measured"] = num
                rows.append(row)
    with open(out / "properties.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return rows


def linear_fields(out: Path) -> list[dict]:
    """Seed 001: grid fields of constant and linear particle data, per density and option
    (1D, CPDI): max error over the interior dofs and over all touched dofs."""
    rows = []
    for option in OPTIONS:
        for dens in DENSITIES:
            b = line_body(dens, DOMAINS["cpdi1"])
            P = b.psi(option)
            touched = np.abs(b.S).sum(axis=0) > 0
            idofs = np.intersect1d(_interior_dofs(b, 1.5 * b.h), np.flatnonzero(touched))
            lin = (P @ b.x[:, 0]) - b.xd[:, 0]
            const = P.sum(axis=1) - 1
            rows.append({"option": option, "particles per cell": dens,
                         "constant, all": np.abs(const[touched]).max(),
                         "linear, interior": np.abs(lin[idofs]).max(), "linear, all": np.abs(lin[touched]).max()})
    return rows


def write_markdown(out: Path, rows: list[dict], lin: list[dict], provenance: Provenance | None = None) -> None:
    """``properties.md``: each property's verdict and number per option, in 1D and 2D."""
    lines = ["# Implied particle basis functions: properties", "",
             (provenance or Provenance.now(comm=MPI.COMM_SELF)).line(), "",
             "1D: a body of 20 particles (2 per cell) "
             "on a 16-cell line; 2D: 2 x 2 particles per unit cell, 6 x 6 cells, on an unstructured triangle "
             "mesh of size 1. Both bodies sit at a generic offset from the grid. "
             "Option 1 = lumped psi, option 2 = consistent (pseudo-inverse) psi. Each entry: does the "
             "claim hold, and the measured number, in 1D and in 2D. 'interior' = dofs (touched by a "
             "particle) or particles more than 1.5 cells inside the body; 'edge' = all touched dofs. "
             "(i): max over interior p, q of abs(Phi_p(x_q) - delta_pq). (ii), (x), (xiv): max abs "
             "deviation. (iii): max abs(sum_p x_p Phi_p(x_i) - x_i). (xi): max change of Phi_p(x + s) "
             "after a shift s of the particles, and max relative error of the rate formula (central "
             "differences against the averaged gradient). (xii): (max - min) of the integral of "
             "Phi_p over 7 shifts in [0, h), over V_p. (xiii): max change of psi under x -> A x "
             "(stretch and shear) of grid and particles, and of Phi_p with the grid fixed.", ""]
    for option in OPTIONS:
        lines += [f"## {option} ({OPTION_NAMES[option]})", "",
                  "| property | " + " | ".join(DOMAINS) + " |", "|---|" + "---|" * len(DOMAINS)]
        for key, text in PROPERTIES:
            cells = []
            for dname in DOMAINS:
                r = next(x for x in rows if x["property"] == key and x["option"] == option and x["domain"] == dname)
                cells.append(f"1D {r['1D holds']}: {r['1D measured']}<br>2D {r['2D tri holds']}: {r['2D tri measured']}")
            lines.append(f"| ({key}) {text} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += ["## Constant and linear particle data on the grid (1D, CPDI domains)", "",
              "| option | particles per cell | constant, all dofs | linear, interior dofs | linear, all dofs |",
              "|---|---|---|---|---|"]
    for r in lin:
        lines.append(f"| {r['option']} | {r['particles per cell']:g} | {r['constant, all']:.2g} | "
                     f"{r['linear, interior']:.2g} | {r['linear, all']:.2g} |")
    (out / "properties.md").write_text("\n".join(lines) + "\n")


def run(out: Path, figures: bool = True, provenance: Provenance | None = None) -> dict:
    """The whole study on this rank; returns the property rows and the linear-field rows
    (``provenance``: what made the outputs, default this process now, written beside them)."""
    out.mkdir(parents=True, exist_ok=True)
    provenance = provenance or Provenance.now(comm=MPI.COMM_SELF)
    provenance.write(out)
    rows = property_table(out)
    lin = linear_fields(out)
    write_markdown(out, rows, lin, provenance)
    if figures:
        figures_1d(out)
        figures_2d(out)
    return {"properties": rows, "linear": lin}
