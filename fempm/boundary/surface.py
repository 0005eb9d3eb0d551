r"""Pressure and traction on tagged parts of the body's surface: :func:`surface_load`.

Facet tags (gmsh physical groups) mark a part of the body's surface where the particles are
seeded. A tagged facet :math:`f` with particles beside it on exactly one side (over all ranks)
gives its area vector :math:`\mathbf A_f = |f|\,\mathbf N_f`, pointing out of the body, to the
particles of the cell beside it that lie nearest to it (the row within 1.5 times the smallest
distance to its plane), in proportion to their volumes. Each particle keeps its share, its
reference area vector :math:`\mathbf A_p`, in ``fields[name]``; :math:`\sum_p \mathbf A_p =
\sum_f \mathbf A_f` exactly, so the load's total force on the undeformed body is right on
every cell type and at any number of particles per cell, and the load sits on the body's own
surface (the particles nearest the tagged facets), not on the mesh's.

As the body deforms, each area vector follows it by Nanson's formula,

.. math::
    \mathbf a_p = J_p \mathbf F_p^{-T} \mathbf A_p = \operatorname{cof}(\mathbf F_p)\, \mathbf A_p,

and the particle's external force is

* a pressure :math:`p(t)` (a follower load, normal to the surface as it turns and stretches):
  :math:`\mathbf f_p = -p(t)\, \mathbf a_p`;
* a traction :math:`\bar{\mathbf t}(t)` per unit reference area (a dead load of fixed total
  force :math:`\bar{\mathbf t} \sum_f |f|`): :math:`\mathbf f_p = \bar{\mathbf t}(t)\, |\mathbf A_p|`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import dolfinx.mesh
import numpy as np
import numpy.typing as npt

from fempm.boundary.tagged import tagged_facets
from fempm.meshes.facets import cells_beside, facet_planes, facet_sums, nearest_row

__all__ = ["SurfaceLoad", "cofactor_apply", "surface_area_vectors", "surface_load"]

@dataclass(frozen=True)
class SurfaceLoad:
    r"""A pressure or a traction on the particles that carry a surface's reference area vectors
    (``fields[field]``, made by :func:`surface_load`).

    Args:
        field: The particle field (n, d) of reference area vectors :math:`\mathbf A_p`.
        pressure: :math:`p`, a number or a function of the time; positive pushes into the body.
        traction: :math:`\bar{\mathbf t}` (d,), per unit reference area, or a function of the
            time returning it.
    """

    field: str
    pressure: float | Callable[[float], float] | None = None
    traction: npt.ArrayLike | Callable[[float], npt.ArrayLike] | None = None

    def forces(self, particles, t: float) -> npt.NDArray:
        r"""The load's force on each particle (n, d) at time ``t`` (zero rows off the surface):
        :math:`-p\, \operatorname{cof}(\mathbf F_p) \mathbf A_p` or :math:`\bar{\mathbf t} |\mathbf A_p|`."""
        if self.field not in particles.fields:
            raise ValueError(f"the particles carry no field {self.field!r} (made by surface_load)")
        A = particles.fields[self.field]
        out = np.zeros_like(A)
        rows = np.flatnonzero(np.any(A != 0.0, axis=1))
        if self.pressure is not None:
            p = float(self.pressure(t) if callable(self.pressure) else self.pressure)
            if not np.isfinite(p):
                raise ValueError(f"the pressure on {self.field!r} is {p} at t = {t:g}")
            out[rows] = -p * cofactor_apply(particles.fields["F"][rows], A[rows])
        else:
            tr = np.asarray(self.traction(t) if callable(self.traction) else self.traction, dtype=np.float64)
            if tr.shape != (A.shape[1],) or not np.all(np.isfinite(tr)):
                raise ValueError(f"the traction on {self.field!r} is {tr.tolist()} at t = {t:g}: expected "
                                 f"{A.shape[1]} finite components")
            out[rows] = np.linalg.norm(A[rows], axis=1)[:, None] * tr
        return out


def cofactor_apply(F: npt.NDArray, A: npt.NDArray) -> npt.NDArray:
    r""":math:`\operatorname{cof}(\mathbf F) \mathbf A = J \mathbf F^{-T} \mathbf A` for (n, d, d)
    and (n, d) arrays (d = 1, 2, 3), with no inverse: in 2D :math:`(F_{11} A_0 - F_{10} A_1,
    F_{00} A_1 - F_{01} A_0)`, in 3D :math:`\sum_J A_J\, \mathbf F_{J+1} \times \mathbf F_{J+2}`
    over the columns :math:`\mathbf F_J` of :math:`\mathbf F`."""
    d = A.shape[1]
    if d == 1:
        return A.copy()
    if d == 2:
        return np.stack([F[:, 1, 1] * A[:, 0] - F[:, 1, 0] * A[:, 1],
                         F[:, 0, 0] * A[:, 1] - F[:, 0, 1] * A[:, 0]], axis=1)
    c = [F[:, :, j] for j in range(3)]
    return sum(A[:, [j]] * np.cross(c[(j + 1) % 3], c[(j + 2) % 3]) for j in range(3))


def surface_area_vectors(particles, facet_tags: dolfinx.mesh.MeshTags, value: int) -> npt.NDArray:
    """Each particle's reference area vector (n, gdim) of the body's surface on the facets
    tagged ``value`` (the module's rule; zero rows elsewhere), from the particles' current
    positions.

    Raises:
        ValueError: Tags that are not facet tags, a tag that marks no facets on any rank, a tag
            none of whose facets has particles beside it, a tag whose facets run through the
            body (particles on both sides).

    Note:
        Collective.
    """
    mesh = particles.mesh
    tdim, gdim = mesh.topology.dim, mesh.geometry.dim
    fdim = tdim - 1
    for a, b in ((tdim, fdim), (fdim, tdim)):
        mesh.topology.create_connectivity(a, b)
    facets = tagged_facets(mesh, facet_tags, value)
    comm = particles.comm
    num_cells = mesh.topology.index_map(tdim).size_local
    occupied = np.zeros(num_cells, dtype=np.bool_)
    occupied[particles.cells[particles.cells < num_cells]] = True
    fmap = mesh.topology.index_map(fdim)
    tag = np.zeros(fmap.size_local + fmap.num_ghosts, dtype=np.bool_)
    tag[facets] = True  # this rank's tagged facets; every rank that has a facet learns if any rank tags it
    beside = cells_beside(mesh, occupied)
    tagged_anywhere = facet_sums(mesh, tag) > 0
    owned = slice(0, fmap.size_local)
    inner = comm.allreduce(int(np.count_nonzero(tagged_anywhere[owned] & (beside[owned] > 1))))
    if inner:
        raise ValueError(f"facet tag {value} runs through the body: {inner} of its facets have particles on both "
                         "sides (a load needs a part of the body's surface)")
    A = np.zeros((len(particles), gdim))
    c2f = mesh.topology.connectivity(tdim, fdim)
    members = np.argsort(particles.cells, kind="stable")
    starts = np.searchsorted(particles.cells[members], np.arange(num_cells + 1))
    for c in np.flatnonzero(occupied):
        facets_c = c2f.links(c)
        loaded = facets_c[tagged_anywhere[facets_c] & (beside[facets_c] == 1)]
        if not len(loaded):
            continue
        rows = members[starts[c]:starts[c + 1]]
        _share(mesh, particles, c, loaded.astype(np.int32), rows, A)
    if not comm.allreduce(bool(np.any(A != 0.0))):
        raise ValueError(f"facet tag {value} marks no part of the body's surface: no particles lie beside its facets")
    return A


def _share(mesh, particles, cell: int, facets: npt.NDArray[np.int32], rows: npt.NDArray, A: npt.NDArray) -> None:
    """Add each facet's area vector (out of ``cell``) to the particles ``rows`` of ``cell`` in
    the row nearest to it, in proportion to their volumes."""
    origin, a = facet_planes(mesh, facets, np.full(len(facets), cell, dtype=np.int32))
    x, v = particles.x[rows], particles.volume[rows]
    for o, af in zip(origin, a):
        depth = np.abs((x - o) @ af) / np.linalg.norm(af)
        near = nearest_row(depth, 1e-12 * depth.max())
        A[rows[near]] += af * (v[near] / v[near].sum())[:, None]


def surface_load(particles, facet_tags: dolfinx.mesh.MeshTags, value: int, *,
                 pressure: float | Callable[[float], float] | None = None,
                 traction: npt.ArrayLike | Callable[[float], npt.ArrayLike] | None = None) -> SurfaceLoad:
    """A pressure or a traction on the part of the body's surface that the facets tagged
    ``value`` mark (the module's rule), for ``Loads(surface=[...])``.

    The particles' reference area vectors are made now, from their current positions (the
    reference configuration), into ``fields["surface_<value>"]`` (kept if there already: two
    loads on one tag share them); they migrate and are checkpointed with the particles.

    Args:
        particles: The particles, in their reference configuration.
        facet_tags: Facet tags of the particles' mesh (gmsh physical groups, e.g. from
            :func:`fempm.meshes.read_msh` or :func:`fempm.meshes.tagged_polygon`).
        value: The tag.
        pressure: A pressure (positive into the body), a number or a function of the time;
            a follower load.
        traction: A traction (gdim,) per unit reference area, or a function of the time
            returning it; a dead load.

    Returns:
        The load.

    Raises:
        ValueError: Neither or both of ``pressure`` and ``traction``, a constant one that is not
            finite or of the wrong shape, and the errors of :func:`surface_area_vectors`.

    Note:
        Collective.
    """
    if (pressure is None) == (traction is None):
        raise ValueError("a surface load takes a pressure or a traction (one of them)")
    gdim = particles.mesh.geometry.dim
    if pressure is not None and not callable(pressure) \
            and not np.isfinite(np.asarray(pressure, dtype=np.float64)).all():
        raise ValueError(f"pressure={pressure!r} must be a finite number (or a function of the time)")
    if traction is not None and not callable(traction):
        tr = np.asarray(traction, dtype=np.float64)
        if tr.shape != (gdim,) or not np.all(np.isfinite(tr)):
            raise ValueError(f"traction={traction!r} must be {gdim} finite components (or a function of the time)")
    field = f"surface_{int(value)}"
    if field not in particles.fields:
        particles.fields[field] = surface_area_vectors(particles, facet_tags, value)
    return SurfaceLoad(field, pressure, traction)
