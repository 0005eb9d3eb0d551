r"""Mapping study: error of the particle-to-grid projection against its run time.

Known fields are sampled at jittered particles and projected onto P1 (lumped and consistent)
and P2 (consistent) spaces, on structured triangles, structured quadrilaterals and unstructured
gmsh triangles, for several mesh sizes and particle densities:

* ``smooth``: :math:`f = \sin(2\pi x)\sin(2\pi y) + x^2 y`,
* ``fe``: a random function of the target space itself (consistent projection must return it
  to solver tolerance; lumped projection does not).

Particle domains (``domains``: point, gimp, cpdi1, cpdi2) select the averaged basis
:math:`\langle N_i \rangle_p` of the projection; the particle values are then the domain
averages by the domain's own rule, :math:`f_p = \sum_q w_{pq} f(y_{pq})` (the point value for
standard MPM), and for the ``fe`` field :math:`f_p = \sum_i \langle N_i \rangle_p u_i`, which
the consistent projection returns exactly. CPDI2 particles are their (unjittered) seeding
sub-cells (``create_particles(..., corners=True)``); the other domains use jittered particles,
with boxes of half-width :math:`\tfrac12 V_p^{1/d}` shrunk where they would reach past the
unit square (they stay centred at the particle).

With point particles the study also maps a velocity field to the grid and back with each
velocity transfer and mass (:mod:`fempm.studies.velocity_mapping`: ``mapping_velocity.csv``
and its section of the summary). For each case the table holds :math:`\|F - f\|_{L^2}`, the wall time of the projection (basis
tabulation, mass assembly, right-hand side and solve; maximum over ranks) and the KSP
iterations. Fitted convergence rates :math:`\|F - f\| \sim h^r` (``numpy.polyfit``) of the
smooth field are in the Markdown summary.
"""

from __future__ import annotations

import csv
import dataclasses
import itertools
import time
from pathlib import Path

import dolfinx.fem
import dolfinx.mesh as dm
import numpy as np
import ufl
from mpi4py import MPI

from fempm.io.plot import plot_error_vs_time
from fempm.meshes.generators import unstructured_rectangle
from fempm.particles.seeding import create_particles
from fempm.studies import velocity_mapping
from fempm.studies.harness import Provenance
from fempm.transfer.basis import ParticleBasis
from fempm.transfer.domains import half_widths, make_domain, step_domain
from fempm.transfer.mapping import SingularMassError
from fempm.transfer.projection import Projector
from fempm.verification.errors import l2_error

__all__ = [
    "COLUMNS", "MESH_KINDS", "SPACES", "convergence_rates", "domain_average", "make_mesh", "random_fe_function",
    "run", "run_case", "smooth", "smooth_ufl", "write",
]

MESH_KINDS = ("structured-tri", "structured-quad", "unstructured-tri")
SPACES = ((1, "lumped"), (1, "consistent"), (2, "consistent"))


def make_mesh(kind: str, n: int, comm: MPI.Comm) -> dm.Mesh:
    if kind == "structured-tri":
        return dm.create_unit_square(comm, n, n)
    if kind == "structured-quad":
        return dm.create_unit_square(comm, n, n, dm.CellType.quadrilateral)
    if kind == "unstructured-tri":
        return unstructured_rectangle(comm, 1.0 / n)
    raise ValueError(f"unknown mesh kind {kind!r}; expected one of {MESH_KINDS}")


def smooth(x):
    return np.sin(2 * np.pi * x[0]) * np.sin(2 * np.pi * x[1]) + x[0] ** 2 * x[1]


def smooth_ufl(mesh):
    x = ufl.SpatialCoordinate(mesh)
    return ufl.sin(2 * ufl.pi * x[0]) * ufl.sin(2 * ufl.pi * x[1]) + x[0] ** 2 * x[1]


def random_fe_function(V: dolfinx.fem.FunctionSpace, seed: int = 0) -> dolfinx.fem.Function:
    """A function of V with partition-independent pseudo-random dof values in [-1, 1)."""
    u = dolfinx.fem.Function(V)
    imap = V.dofmap.index_map
    g = imap.local_to_global(np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32))
    v = np.sin(12.9898 * g + 78.233 * seed) * 43758.5453
    u.x.array[:] = 2.0 * (v - np.floor(v)) - 1.0
    return u


def domain_average(f, particles, domain) -> np.ndarray:
    r""":math:`f_p = \sum_q w_{pq} f(y_{pq})` over the domain's sample points (f takes x of shape
    (gdim, m), as ``Function.interpolate``); exact-GIMP boxes by an 8-point Gauss rule per axis
    (the field is smooth over the box)."""
    if getattr(domain, "exact", False):
        domain = dataclasses.replace(domain, order=8)
    smp = domain.samples(particles)
    n, q, d = smp.x.shape
    return np.einsum("nq,nq->n", smp.w, np.asarray(f(smp.x.reshape(n * q, d).T)).reshape(n, q))


def run_case(mesh, particles, degree: int, mass: str, field: str, domain: str = "point") -> dict:
    comm = mesh.comm
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", degree))
    dom = make_domain(domain)
    if field == "smooth":
        values, exact = domain_average(smooth, particles, dom), smooth_ufl(mesh)
    else:
        exact = random_fe_function(V)
        values = ParticleBasis(V, particles, domain=dom).gather(exact.x.array[:, None])[:, 0]
    comm.Barrier()
    t0 = time.perf_counter()
    projector = Projector(V, particles, mass=mass, domain=dom)
    F = projector.project(values)
    wall = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    return {
        "l2_error": l2_error(F, exact),
        "time_s": wall,
        "ksp_its": projector.iterations[0] if projector.iterations else 0,
        "dofs": V.dofmap.index_map.size_global,
        "inactive": projector.num_inactive,
    }


def run(
    sizes=(8, 16, 32),
    ppcs=(4,),
    kinds=MESH_KINDS,
    fields=("smooth", "fe"),
    out: Path = Path("output/study-mapping"),
    comm: MPI.Comm = MPI.COMM_WORLD,
    jitter: float = 0.5,
    domains=("point",),
    log=print,
    provenance: Provenance | None = None,
    velocity_kinds=None,
) -> list[dict]:
    """Run every case, write ``mapping.csv``, ``mapping.md``, ``mapping.png`` and
    ``provenance.json`` into ``out``; with point particles also the velocity round trips on the
    mesh kinds ``velocity_kinds`` (default ``kinds``; :mod:`fempm.studies.velocity_mapping`).

    Note:
        Collective.
    """
    provenance = provenance or Provenance.now(comm=comm)
    for domain in domains:
        make_domain(domain)  # unknown names fail before any work
    rows = []
    warm = make_mesh("structured-tri", 4, comm)  # first-call costs (imports, PETSc set-up) untimed
    run_case(warm, create_particles(warm, 4), 1, "consistent", "smooth")
    for kind, n in itertools.product(kinds, sizes):
        mesh = make_mesh(kind, n, comm)
        ncells = mesh.topology.index_map(2).size_global
        h = 1.0 / np.sqrt(ncells / (2 if "tri" in kind else 1))  # equivalent structured size
        for ppc, domain in itertools.product(ppcs, domains):
            if step_domain(domain).tracks_corners:  # the particles are their sub-cells
                particles = create_particles(mesh, ppc, corners=True)
            else:
                particles = create_particles(mesh, ppc, jitter=jitter, seed=1)
                # boxes (GIMP, CPDI1) centred at the particle, shrunk where they would reach past the unit square
                ell = half_widths(particles)
                particles.fields["lp"] = np.minimum(ell, np.minimum(particles.x, 1.0 - particles.x) * (1 - 1e-9))
            for (degree, mass), field in itertools.product(SPACES, fields):
                try:
                    r = run_case(mesh, particles, degree, mass, field, domain)
                except SingularMassError:  # too few particles for the space: no row
                    if comm.rank == 0:
                        log(f"{kind:17s} n={n:4d} ppc={ppc:2d} {domain} P{degree} {mass}: singular mass matrix, skipped")
                    continue
                row = {"mesh": kind, "n": n, "h": h, "cells": ncells, "ppc": ppc, "domain": domain,
                       "particles": particles.num_global, "field": field, "space": f"P{degree}", "mass": mass, **r}
                rows.append(row)
                if comm.rank == 0:
                    log(f"{kind:17s} n={n:4d} ppc={ppc:2d} {domain:5s} {field:6s} P{degree} {mass:10s} "
                        f"L2={r['l2_error']:.3e}  t={r['time_s']:.4f}s  its={r['ksp_its']}")
    velocity_rows = (velocity_mapping.run(make_mesh, kinds if velocity_kinds is None else velocity_kinds, sizes, ppcs,
                                          comm, log) if "point" in domains else [])
    if comm.rank == 0:
        write(rows, out, provenance, velocity_rows)
    return rows


def convergence_rates(rows: list[dict]) -> list[dict]:
    """Fitted slope of log(error) against log(h) per series of the smooth field."""
    out = []
    series = ("mesh", "space", "mass", "ppc", "domain")
    keys = sorted({tuple(r.get(k, "point") for k in series) for r in rows if r["field"] == "smooth"})
    for key in keys:
        rs = [r for r in rows if r["field"] == "smooth" and tuple(r.get(k, "point") for k in series) == key]
        if len(rs) >= 2:
            slope = np.polyfit(np.log([r["h"] for r in rs]), np.log([r["l2_error"] for r in rs]), 1)[0]
            out.append({**dict(zip(series, key)), "rate": slope})
    return out


COLUMNS = ["mesh", "n", "cells", "ppc", "domain", "particles", "field", "space", "mass", "l2_error", "time_s", "ksp_its", "dofs", "inactive"]


def write(rows: list[dict], out: Path, provenance: Provenance | None = None, velocity_rows=()) -> None:
    """``mapping.csv``, ``mapping.md`` (the rows and the fitted rates, and the velocity round
    trips ``velocity_rows``: :mod:`fempm.studies.velocity_mapping`), ``mapping.png``,
    ``mapping_velocity.csv`` and ``provenance.json`` into ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    provenance = provenance or Provenance.now(comm=MPI.COMM_SELF)
    provenance.write(out)
    with open(out / "mapping.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS + ["h"])
        w.writeheader()
        w.writerows(rows)
    fmt = {"l2_error": "{:.3e}", "time_s": "{:.4f}", "h": "{:.4f}"}
    lines = ["# Mapping study: L2 error and wall time of the particle-to-grid projection", "", provenance.line(), "",
             "| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for r in rows:
        lines.append("| " + " | ".join(fmt.get(c, "{}").format(r[c]) for c in COLUMNS) + " |")
    rates = convergence_rates(rows)
    if rates:
        lines += ["", "## Fitted convergence rates (smooth field, error ~ h^rate)", "",
                  "| mesh | space | mass | ppc | domain | rate |", "|---|---|---|---|---|---|"]
        lines += [f"| {r['mesh']} | {r['space']} | {r['mass']} | {r['ppc']} | {r['domain']} | {r['rate']:.2f} |"
                  for r in rates]
    lines += velocity_mapping.write(list(velocity_rows), out)
    (out / "mapping.md").write_text("\n".join(lines) + "\n")
    plot_error_vs_time(rows, out / "mapping.png", title="fempm mapping study: error vs projection time")
