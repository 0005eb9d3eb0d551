r"""Grid conditions on tagged facets (gmsh physical groups): :func:`tagged`.

The nodes of the facets that carry a tag are held as a fixed, slip or frictional wall. A slip
or frictional wall takes each node's normal from the facets around it: the outward normals of
the tagged facets that hold the node, weighted by their size (length, area), summed and made
unit,

.. math::
    n_i = \frac{\sum_{f \ni i} |f|\, n_f}{\big|\sum_{f \ni i} |f|\, n_f\big|},

so that an inclined or curved boundary slips along itself (at a corner the node slips along the
bisector). Under MPI the sums run over the facets each rank owns and are added across ranks
(a DOLFINx vector's reverse scatter), so every rank holds the same normals at shared nodes.

Where a slip or frictional wall ends at an edge of an opening (the boundary turns outward there,
round a reflex corner of the mesh: a hopper's outlet lip, :func:`open_ends`), its end node is
left free: the material beside it passes the wall's end rather than meeting the wall, and a
condition there would turn it along the wall over the node's whole support, a cell into the
opening. Holding the lip narrowed a hopper's outlet by about 0.7 cell on each side (the silo's
discharge then rose with refinement as :math:`(D - 1.4 h)^{3/2}`, docs/silo).
"""

from __future__ import annotations

import dolfinx.fem
import dolfinx.la
import dolfinx.mesh
import numpy as np
import numpy.typing as npt

from fempm.boundary.walls import Fixed, Friction, Slip, friction_wall
from fempm.meshes.facets import facet_area_vectors

__all__ = ["KINDS", "boundary_only", "facet_normals", "open_ends", "tagged", "tagged_facets"]

#: the kinds of condition :func:`tagged` makes
KINDS = ("fixed", "slip", "friction")


def tagged_facets(mesh: dolfinx.mesh.Mesh, facet_tags: dolfinx.mesh.MeshTags, value: int) -> npt.NDArray[np.int32]:
    """The local facets with tag ``value``; a ValueError when the tags were made on another mesh,
    are not facet tags or no rank's facets carry ``value`` (its message lists the tags there
    are). Collective."""
    fdim = mesh.topology.dim - 1
    if facet_tags.topology is not mesh.topology._cpp_object:
        raise ValueError(f"facet tag {value}: the facet tags were made on another mesh than the space's (make them on "
                         "V.mesh: fempm.meshes.read_msh returns a mesh with its own facet tags)")
    if facet_tags.dim != fdim:
        raise ValueError(f"tagged conditions and loads need facet tags (dimension {fdim}); these tags are of dimension "
                         f"{facet_tags.dim}")
    comm = mesh.comm
    facets = facet_tags.find(int(value))
    if not comm.allreduce(len(facets)):  # an unknown tag, or one no rank's facets carry
        known = sorted(set().union(*comm.allgather(set(np.unique(facet_tags.values).tolist()))))
        raise ValueError(f"unknown facet tag {value}: it marks no facets on any rank (the facet tags hold "
                         f"{', '.join(map(str, known)) or 'none'})")
    return facets


def boundary_only(mesh: dolfinx.mesh.Mesh, facets: npt.NDArray[np.int32], value: int, what: str) -> None:
    """A ValueError naming tag ``value`` when some of its local ``facets`` lie inside the mesh
    (two cells share them, on any rank), where ``what`` has nothing to act on. Collective."""
    fdim = mesh.topology.dim - 1
    mesh.topology.create_connectivity(fdim, mesh.topology.dim)
    exterior = dolfinx.mesh.exterior_facet_indices(mesh.topology)
    owned = facets[facets < mesh.topology.index_map(fdim).size_local]
    inner = mesh.comm.allreduce(int(np.count_nonzero(~np.isin(owned, exterior))))
    if inner:
        raise ValueError(f"facet tag {value} marks {inner} facet(s) inside the mesh: {what} acts on the mesh's "
                         "boundary only")


def facet_normals(V: dolfinx.fem.FunctionSpace, facets: npt.NDArray[np.int32]) -> tuple[npt.NDArray, npt.NDArray]:
    """The (block) dofs of the local ``facets`` (owned + ghost, sorted) and their unit normals
    (k, gdim) averaged over the facets as in the module; a dof whose normals cancel has a zero
    row. Collective."""
    mesh = V.mesh
    tdim, gdim = mesh.topology.dim, mesh.geometry.dim
    fdim = tdim - 1
    for a, b in ((fdim, tdim), (tdim, fdim), (fdim, 0)):
        mesh.topology.create_connectivity(a, b)
    owned = facets[facets < mesh.topology.index_map(fdim).size_local]  # each facet counted on one rank
    n = facet_area_vectors(mesh, owned)
    f2c, c2f = mesh.topology.connectivity(fdim, tdim), mesh.topology.connectivity(tdim, fdim)
    layout = V.dofmap.dof_layout
    sums = dolfinx.la.vector(V.dofmap.index_map, bs=gdim + 1)  # normal sums and a count per dof
    acc = sums.array.reshape(-1, gdim + 1)
    for f, nf in zip(owned, n):
        cell = f2c.links(f)[0]
        local = int(np.flatnonzero(c2f.links(cell) == f)[0])
        dofs = V.dofmap.cell_dofs(cell)[layout.entity_closure_dofs(fdim, local)]
        acc[dofs, :gdim] += nf
        acc[dofs, gdim] += 1.0
    sums.scatter_reverse(dolfinx.la.InsertMode.add)
    sums.scatter_forward()
    acc = sums.array.reshape(-1, gdim + 1)
    dofs = np.flatnonzero(acc[:, gdim] > 0).astype(np.int32)
    length = np.linalg.norm(acc[dofs, :gdim], axis=1)
    scale = np.where(length > 1e-12 * length.max(initial=0.0), 1.0 / np.where(length > 0, length, 1.0), 0.0)
    return dofs, acc[dofs, :gdim] * scale[:, None]


def tagged(V: dolfinx.fem.FunctionSpace, facet_tags: dolfinx.mesh.MeshTags, value: int, kind: str,
           friction: float = 0.0) -> Fixed | Slip | Friction:
    """A wall on the facets tagged ``value``: the nodes of those facets held as ``kind``.

    Args:
        V: The velocity space.
        facet_tags: Facet tags of ``V``'s mesh (gmsh physical groups, e.g. from
            :func:`fempm.meshes.read_msh` or :func:`fempm.meshes.tagged_polygon`).
        value: The tag.
        kind: ``"fixed"`` (every component 0), ``"slip"`` (no flow through the boundary, along
            the facet normals averaged at each node) or ``"friction"`` (Coulomb friction with
            coefficient ``friction`` against the same normals, the kernel the other walls and
            contact use: :func:`fempm.boundary.coulomb.coulomb`).
        friction: The friction coefficient of ``kind="friction"``.

    Returns:
        The condition, for ``ExplicitSolver(bcs=[...])``.

    Raises:
        ValueError: An unknown kind, tags that are not facet tags, a tag that marks no facets
            on any rank (its message lists the tags there are), a friction coefficient that is negative or not finite, nodes where the facet normals
            cancel (a slip or friction wall on a boundary that folds back on itself).

    Note:
        Collective.
    """
    if kind not in KINDS:
        raise ValueError(f"unknown kind={kind!r} of tagged condition; expected one of {', '.join(KINDS)}")
    facets = tagged_facets(V.mesh, facet_tags, value)
    dofs, normals = facet_normals(V, facets)
    if kind == "fixed":
        return Fixed(dofs)
    cancel = V.mesh.comm.allreduce(int(np.count_nonzero(~np.any(normals != 0.0, axis=1))))
    if cancel:
        raise ValueError(f"facet tag {value}: the facet normals cancel at {cancel} node(s) (a boundary that folds back "
                         f"on itself); a {kind} wall needs one side")
    keep = ~open_ends(V, facets, dofs)
    dofs, normals = dofs[keep], _common_normal(normals[keep], V.mesh.comm)
    if kind == "slip":
        return Slip(dofs, normals)
    return friction_wall(dofs, normals, friction)


def open_ends(V: dolfinx.fem.FunctionSpace, facets: npt.NDArray[np.int32], dofs: npt.NDArray[np.int32]
              ) -> npt.NDArray[np.bool_]:
    """Which of a wall's ``dofs`` (of :func:`facet_normals`) sit at the wall's open ends: a
    vertex of the tagged ``facets`` that an untagged boundary facet shares and that facet leaves
    to the outer side of a tagged facet's plane there (a reflex corner of the mesh's boundary,
    where the wall ends at an opening). Collective (the boundary facets are gathered)."""
    mesh = V.mesh
    tdim, gdim = mesh.topology.dim, mesh.geometry.dim
    fdim = tdim - 1
    mesh.topology.create_connectivity(fdim, tdim)
    num_owned = mesh.topology.index_map(fdim).size_local
    exterior = dolfinx.mesh.exterior_facet_indices(mesh.topology)
    exterior = exterior[exterior < num_owned]
    tagged_owned = np.intersect1d(facets[facets < num_owned], exterior)
    others = np.setdiff1d(exterior, tagged_owned)
    x = mesh.geometry.x[:, :gdim]
    ids = np.asarray(mesh.geometry.input_global_indices, dtype=np.int64)
    nv = fdim + 1 if mesh.topology.cell_type.name in ("interval", "triangle", "tetrahedron") else 2**fdim

    def corners(f):  # (global ids (k, nv), coordinates (k, nv, gdim)) of facets' vertices
        nodes = dolfinx.mesh.entities_to_geometry(mesh, fdim, f)[:, :nv] if len(f) else np.zeros((0, nv), np.int32)
        return ids[nodes], x[nodes]

    comm = mesh.comm
    gather = lambda a: np.concatenate(comm.allgather(a))  # noqa: E731
    (wall_ids, wall), (rest_ids, rest) = (tuple(map(gather, corners(f))) for f in (tagged_owned, others))
    normal = gather(facet_area_vectors(mesh, tagged_owned) if len(tagged_owned) else np.zeros((0, gdim)))
    if not len(wall) or not len(rest):
        return np.zeros(len(dofs), dtype=bool)
    normal = normal / np.linalg.norm(normal, axis=1, keepdims=True)
    at: dict[int, list[int]] = {}  # vertex id -> the untagged boundary facets that hold it
    for k, row in enumerate(rest_ids):
        for i in row:
            at.setdefault(int(i), []).append(k)
    ends = []
    for f in range(len(wall)):
        for i, v in zip(wall_ids[f], wall[f]):
            near = at.get(int(i))
            if near:
                step = rest[near] - v  # the untagged facets' vertices against the wall's plane
                if (step @ normal[f]).max() > 1e-6 * np.linalg.norm(step, axis=2).max():
                    ends.append(v)
    if not ends:
        return np.zeros(len(dofs), dtype=bool)
    X = V.tabulate_dof_coordinates()[dofs, :gdim]
    tol = 1e-9 * np.ptp(x, axis=0).max() if len(x) else 0.0
    return np.any(np.linalg.norm(X[:, None, :] - np.unique(np.array(ends), axis=0)[None], axis=2) <= tol, axis=1)


def _common_normal(normals: npt.NDArray, comm) -> npt.NDArray:
    """One normal (d,) where every rank's nodes share it (a straight wall: an axis-aligned one
    then holds a component, :class:`Slip`), else the per-node normals."""
    d = normals.shape[1]
    first = normals[0] if len(normals) else np.full(d, np.nan)
    candidates = [c for c in comm.allgather(first) if np.all(np.isfinite(c))]
    common = candidates[0]
    same = all(np.allclose(c, common, atol=1e-12) for c in candidates) and np.allclose(normals, common, atol=1e-12)
    if comm.allreduce(int(not same)):
        return normals
    axis = np.flatnonzero(np.abs(np.abs(common) - 1.0) < 1e-12)
    if len(axis) == 1:  # exactly along an axis
        n = np.zeros(d)
        n[axis[0]] = np.sign(common[axis[0]])
        return n
    return common
