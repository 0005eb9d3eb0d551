r"""External loads of the explicit step: body forces and particle tractions.

A body force is per unit mass, :math:`f_i \mathrel{+}= \sum_p M_p b_p N_{ip}`; a traction acts on
the particles that carry a loaded surface, :math:`f_i \mathrel{+}= \sum_p \bar t_p A_p N_{ip}`
with :math:`A_p` the particle's share of that surface.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import dolfinx.la
import dolfinx.mesh
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.boundary.surface import SurfaceLoad
from fempm.meshes.facets import cells_beside, facet_planes, nearest_row

__all__ = [
    "Loads", "body_force_at", "boundary_shares", "external_forces", "surface_areas", "surface_shares",
    "takes_reference_positions",
]


@dataclass
class Loads:
    r"""External loads; a term left None is never assembled.

    Args:
        body_force: An acceleration (d,) per unit mass, or a function of the current positions
            ``x`` (n, d) and the time, ``f(x, t)``, or also of the reference positions
            ``f(x, t, X)`` (the particles' ``fields["X0"]``, e.g. a manufactured body force
            :math:`b(X, t)`), returning (n, d); the number of its positional parameters
            decides which is called.
        traction: A function ``t -> (n, d)``, the traction :math:`\bar t_p` on each particle
            (zero rows away from the loaded surface), applied as the force :math:`\bar t_p A_p`
            with :math:`A_p` the particle's share of the loaded surface: ``fields["area"]``
            when the particles carry it (:func:`surface_areas`), else the body's boundary
            facets next to the loaded particles (:func:`boundary_shares`, exact on every cell
            type).
        surface: Pressures and tractions on tagged parts of the body's surface, following it
            as it deforms (:func:`fempm.boundary.surface.surface_load`).
    """

    body_force: npt.ArrayLike | Callable | None = None
    traction: Callable[[float], npt.NDArray] | None = None
    surface: Sequence[SurfaceLoad] = ()

    @property
    def any(self) -> bool:
        """Whether there is a load at all."""
        return self.body_force is not None or self.per_particle

    @property
    def per_particle(self) -> bool:
        """Whether the loads need a pass over the particles: anything but a constant body
        force (or none)."""
        return self.traction is not None or bool(self.surface) or callable(self.body_force)


def takes_reference_positions(fn: Callable) -> bool:
    """Whether a body-force callable takes ``(x, t, X)`` (three positional parameters) rather
    than ``(x, t)``."""
    try:
        params = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):  # builtins without a signature: the (x, t) form
        return False
    if any(p.kind == p.VAR_POSITIONAL for p in params):
        return True
    positional = [p for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    return len(positional) >= 3


def surface_areas(volumes: npt.NDArray, loaded: npt.NDArray[np.bool_], measure: float, comm) -> npt.NDArray:
    r"""Each loaded particle's share :math:`A_p = |\Gamma|\, V_p / \sum_{q\ loaded} V_q` of a
    loaded surface of measure ``measure`` (length in 2D, area in 3D), 0 elsewhere, so that a
    uniform traction :math:`\bar t` applies exactly the total force :math:`\bar t |\Gamma|`
    (collective: the sum runs over all ranks)."""
    total = comm.allreduce(float(np.sum(volumes[loaded])))
    if total <= 0:
        raise ValueError("no particle carries the loaded surface")
    return np.where(loaded, measure * volumes / total, 0.0)


def body_force_at(b, particles, t: float) -> npt.NDArray:
    """The body force per unit mass at the particles (n, d): ``b`` a constant (d,) or a callable
    ``(x, t)`` / ``(x, t, X)`` (see :class:`Loads`); a wrong shape is a ValueError."""
    if not callable(b):
        b = np.asarray(b, float)
        if b.shape != (particles.gdim,):
            raise ValueError(f"the body force has shape {b.shape}, expected ({particles.gdim},)")
        return np.broadcast_to(b, particles.x.shape)
    if takes_reference_positions(b):
        acc = b(particles.x, t, particles.fields["X0"])
    else:
        acc = b(particles.x, t)
    acc = np.asarray(acc, dtype=np.float64)
    if acc.shape != particles.x.shape:
        raise ValueError(f"the body force returned shape {acc.shape} for {len(particles)} particles in "
                         f"{particles.gdim}D (expected {particles.x.shape})")
    return acc


def _facet_geometry(mesh, facets: npt.NDArray[np.int32]) -> tuple[npt.NDArray, npt.NDArray, npt.NDArray]:
    """(a point, the unit normal, the measure) of each facet
    (:func:`fempm.meshes.facets.facet_planes`)."""
    origin, a = facet_planes(mesh, facets)
    measure = np.linalg.norm(a, axis=1)
    return origin, a / measure[:, None], measure


def boundary_shares(particles, loaded: npt.NDArray[np.bool_]) -> npt.NDArray:
    r"""Each loaded particle's share of the loaded part of the body's surface, -1 for the
    particles not loaded (collective).

    The body's surface is made of the facets with exactly one occupied cell (a cell holding
    particles) on either side, over all ranks. A surface facet :math:`F` of a cell :math:`c` is
    loaded when

    * the loaded particles lie next to it: more than half of the row of :math:`c`'s particles
      nearest to :math:`F` (within 1.5 times the smallest distance to its plane) are loaded,
      and the loaded particles of :math:`c` all lie nearer to :math:`F` than its other
      particles (or, where all of :math:`c`'s particles are loaded, no cell behind :math:`F`,
      across a facet of :math:`c` facing away from it, holds loaded particles): this drops
      the facets that a layer along another face only reaches at the body's edges (where no
      facet of :math:`c` passes, the layer is thicker than a row, and the facets next to it
      are taken);
    * the loaded surface goes on across its vertices: another such facet of about its
      orientation (outward normals within 60 degrees) shares a vertex with it (unless no
      facet anywhere has such a neighbour: a load on one facet).

    The measure of the loaded facets of :math:`c` is shared by :math:`c`'s loaded particles in
    proportion to their volume. A layer of loaded particles one row of the seeding lattice
    thick along a boundary of cell facets then carries exactly the traction times the
    boundary's measure, on every cell type and at any number of particles per cell; a thicker
    layer that wraps round an edge of the body adds the facets it covers there (give
    ``fields["area"]``, :func:`surface_areas`, to load exactly a layer of any shape)."""
    mesh = particles.mesh
    tdim, fdim = mesh.topology.dim, mesh.topology.dim - 1
    mesh.topology.create_entities(fdim)
    for a, b in ((tdim, fdim), (fdim, tdim), (fdim, 0)):
        mesh.topology.create_connectivity(a, b)
    c2f, f2v = mesh.topology.connectivity(tdim, fdim), mesh.topology.connectivity(fdim, 0)
    cmap = mesh.topology.index_map(tdim)
    num_cells = cmap.size_local
    links = np.asarray(c2f.array).reshape(num_cells + cmap.num_ghosts, -1)
    cells = particles.cells
    occupied, holds_loaded = np.zeros(num_cells, dtype=np.bool_), np.zeros(num_cells, dtype=np.bool_)
    occupied[cells[cells < num_cells]] = True
    holds_loaded[cells[loaded & (cells < num_cells)]] = True
    surface = cells_beside(mesh, occupied) == 1.0
    across = cells_beside(mesh, holds_loaded)  # cells with loaded particles at each facet
    loaded_rows = np.flatnonzero(loaded)
    loaded_rows = loaded_rows[np.argsort(cells[loaded_rows], kind="stable")]
    by_cell = np.split(loaded_rows, np.flatnonzero(np.diff(cells[loaded_rows])) + 1) if len(loaded_rows) else []
    cand_cell, cand_facet, cand_normal, cand_measure = _loaded_facets(particles, loaded, links, by_cell, surface, across)
    parallel = _continued(particles, f2v, cand_facet, cand_normal)
    share = np.where(loaded, 0.0, -1.0)
    for rows in by_cell:
        keep = (cand_cell == cells[rows[0]]) & parallel
        if keep.any():
            v = particles.volume[rows]
            share[rows] = float(cand_measure[keep].sum()) * v / v.sum()
    return share


def _loaded_facets(particles, loaded: npt.NDArray[np.bool_], links: npt.NDArray, by_cell: list, surface: npt.NDArray,
                   across: npt.NDArray) -> tuple[npt.NDArray, npt.NDArray, npt.NDArray, npt.NDArray]:
    """(cell, facet, outward normal, measure) of the surface facets the loaded particles of each
    cell (``by_cell``: their rows, cell by cell) lie next to (:func:`boundary_shares`)."""
    mesh, cells = particles.mesh, particles.cells
    d = mesh.geometry.dim
    members = np.argsort(cells, kind="stable")
    starts = np.searchsorted(cells[members], np.arange(mesh.topology.index_map(mesh.topology.dim).size_local + 1))
    cand_cell, cand_facet, cand_normal, cand_measure = [], [], [], []
    for rows in by_cell:
        c = int(cells[rows[0]])
        facets = links[c]
        inside = members[starts[c]:starts[c + 1]]  # all particles of c
        origin, normal, measure = _facet_geometry(mesh, facets.astype(np.int32))
        side = np.einsum("fpd,fd->fp", particles.x[inside][None, :, :] - origin[:, None, :], normal)
        normal = normal * -np.sign(side.mean(axis=1))[:, None]  # outward: away from the particles
        depth = np.abs(side)
        lit_p = loaded[inside]
        next_to, thin = [], []
        for k in np.flatnonzero(surface[facets]):
            row = nearest_row(depth[k], 1e-12 * measure[k])
            if not 2 * np.count_nonzero(row & lit_p) > np.count_nonzero(row):
                continue
            next_to.append(k)
            if lit_p.all():  # behind it, across the facets of c facing away, no loaded cell
                if not np.any(across[facets[(normal @ normal[k]) < -0.3]] > 1.0):
                    thin.append(k)
            elif depth[k][lit_p].max() < depth[k][~lit_p].min():
                thin.append(k)
        for k in thin or next_to:  # a thicker layer: the facets it lies next to
            cand_cell.append(c)
            cand_facet.append(facets[k])
            cand_normal.append(normal[k])
            cand_measure.append(measure[k])
    return (np.asarray(cand_cell, dtype=np.int64), np.asarray(cand_facet, dtype=np.int64),
            np.asarray(cand_normal, dtype=np.float64).reshape(-1, d), np.asarray(cand_measure))


def _continued(particles, f2v, cand_facet: npt.NDArray, cand_normal: npt.NDArray) -> npt.NDArray[np.bool_]:
    """Which candidate facets the loaded surface goes on from: another candidate of about their
    orientation (normals within 60 degrees) shares a vertex with them, over the ranks (all of
    them where no candidate anywhere has such a neighbour: a load on one facet). Collective."""
    mesh = particles.mesh
    d = mesh.geometry.dim
    # the sums of the candidates' outward normals at each vertex, over the ranks
    sums = dolfinx.la.vector(mesh.topology.index_map(0), d, dtype=np.float64)
    width = len(f2v.links(0)) if len(f2v.array) else 1
    vertices = np.asarray(f2v.array).reshape(-1, width)[cand_facet] if len(cand_facet) else \
        np.zeros((0, width), dtype=np.int32)
    np.add.at(sums.array.reshape(-1, d), vertices.ravel(), np.repeat(cand_normal, width, axis=0))
    sums.scatter_reverse(dolfinx.la.InsertMode.add)
    sums.scatter_forward()
    at = sums.array.reshape(-1, d)
    parallel = (np.einsum("fvd,fd->fv", at[vertices] - cand_normal[:, None, :], cand_normal) > 0.5).any(axis=1)
    if not particles.comm.allreduce(bool(parallel.any()), op=MPI.LOR):
        parallel[:] = True  # one loaded facet (on no rank another beside it)
    return parallel


def surface_shares(particles, loaded: npt.NDArray[np.bool_]) -> npt.NDArray:
    """The particles' shares of the loaded surface (collective): ``fields["area"]`` when the
    particles carry it (e.g. from :func:`surface_areas`), else the body's loaded boundary
    facets shared by the loaded particles (:func:`boundary_shares`), computed when the traction
    first loads particles and kept in ``fields["surface_share"]`` (-1: not loaded then),
    computed again when it loads a particle that had no share."""
    f = particles.fields
    if "area" in f:
        return f["area"]
    share = f.get("surface_share")
    stale = share is None or bool(np.any(loaded & (share < 0)))
    if particles.comm.allreduce(stale, op=MPI.LOR) and particles.comm.allreduce(bool(loaded.any()), op=MPI.LOR):
        share = f["surface_share"] = boundary_shares(particles, loaded)
    return np.zeros(len(particles)) if share is None else np.maximum(share, 0.0)


def external_forces(loads, particles, t: float) -> npt.NDArray:
    r"""The external force on each particle (n, d) at time ``t``:
    :math:`f^{ext}_p = M_p b_p + \bar t_p A_p` plus the surface loads (the terms ``loads`` declares;
    zeros without any)."""
    p = particles
    f = np.zeros((len(p), p.gdim))
    if loads.body_force is not None:
        f += p.mass[:, None] * body_force_at(loads.body_force, p, t)
    if loads.traction is not None:
        traction = np.asarray(loads.traction(t), dtype=np.float64)
        if traction.shape != f.shape:
            raise ValueError(f"the traction returned shape {traction.shape} for {len(p)} particles in {p.gdim}D "
                             f"(expected {f.shape})")
        f += traction * surface_shares(p, np.any(traction != 0.0, axis=1))[:, None]
    for load in loads.surface:
        f += load.forces(p, t)
    return f
