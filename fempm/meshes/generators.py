"""Unstructured meshes from gmsh (optional dependency ``gmsh``, imported lazily).

``read_msh`` reads a ``.msh`` file on rank 0 and distributes it; ``unstructured_rectangle``,
``tagged_polygon`` and ``unstructured_box`` generate meshes of a given size, kept in the mesh
cache (:mod:`fempm.meshes.cache`) and refined uniformly on every rank on request
(``refine``, :mod:`fempm.meshes.refinement`). Works with DOLFINx 0.10+
(``dolfinx.io.gmsh``) and earlier (``dolfinx.io.gmshio``).
"""

from __future__ import annotations

from pathlib import Path

import dolfinx
from mpi4py import MPI

from fempm.meshes.cache import cached
from fempm.meshes.refinement import check_refine, refined
from fempm.timings import timed

__all__ = ["MESHES", "MeshFileError", "read_msh", "tagged_polygon", "unstructured_box", "unstructured_polygon",
           "unstructured_rectangle"]

#: the gmsh meshes that ship with fempm (demos, tests, scenes)
MESHES = Path(__file__).resolve().parents[2] / "meshes"


def _gmshio():
    try:
        from dolfinx.io import gmsh as gmshio
    except ImportError:  # DOLFINx < 0.10
        from dolfinx.io import gmshio
    return gmshio


def _gmsh():
    try:
        import gmsh
    except ImportError as e:  # pragma: no cover - depends on the installation
        raise ImportError("unstructured meshes need gmsh: pip install 'fempm[mesh]' (or gmsh)") from e
    return gmsh


class MeshFileError(ValueError):
    """A file that is not a readable gmsh mesh (raised on every rank alike)."""


@timed("mesh_s")
def read_msh(path: str | Path, comm: MPI.Comm = MPI.COMM_WORLD, gdim: int | None = None):
    """Read a gmsh ``.msh`` file; returns DOLFINx ``MeshData`` (mesh, cell_tags, facet_tags, ...).

    ``gdim`` defaults to the dimension of the highest-dimensional cells. Rank 0 reads the file;
    a missing, empty, corrupt or non-mesh file, or one without a physical group of its cells,
    is a :class:`MeshFileError` on every rank that names the file (and what gmsh said), not
    gmsh's or DOLFINx's words alone. Collective.
    """
    path = Path(path)
    gmsh = _gmsh()
    dim, error = 0, None
    if comm.rank == 0:
        if not path.is_file():
            error = f"mesh file {str(path)!r} does not exist"
        else:
            _start(gmsh)
            try:
                gmsh.open(str(path))
                dim = gmsh.model.getDimension()
                if dim < 1 or not len(gmsh.model.mesh.getElements(dim)[0]):
                    error = f"{str(path)!r} is not a readable gmsh mesh: it holds no cells"
                elif not gmsh.model.getPhysicalGroups(dim):
                    error = (f"{str(path)!r} has no physical group of its {dim}-dimensional cells: DOLFINx reads the "
                             "cells of physical groups only (mark them in gmsh: Physical Surface or Physical Volume)")
            except Exception as e:  # noqa: BLE001 - gmsh raises plain Exceptions with its own words
                error = f"{str(path)!r} is not a readable gmsh mesh (gmsh: {str(e).strip() or type(e).__name__})"
            if error is not None:
                gmsh.finalize()
    dim, error = comm.bcast((dim, error), root=0)
    if error is not None:
        raise MeshFileError(error)
    gdim = dim if gdim is None else gdim
    data = _gmshio().model_to_mesh(gmsh.model, comm, 0, gdim=gdim)
    gmsh.finalize() if comm.rank == 0 else None
    return data


def _start(gmsh) -> None:
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)


def _model_to_data(gmsh, comm: MPI.Comm, gdim: int):
    data = _gmshio().model_to_mesh(gmsh.model, comm, 0, gdim=gdim)
    gmsh.finalize() if comm.rank == 0 else None
    return data


def _generated(comm: MPI.Comm, generator: str, params: dict, gdim: int, build, refine: int):
    """The mesh ``build(gmsh)`` models on rank 0, from the mesh cache if it holds it
    (:mod:`fempm.meshes.cache`; ``params`` its key), refined ``refine`` times on every rank
    (:func:`fempm.meshes.refinement.refined`; ``refine`` checked by :func:`_coarse` before). Collective."""
    gmsh = _gmsh()

    def make():
        if comm.rank == 0:
            _start(gmsh)
            build(gmsh)
        return _model_to_data(gmsh, comm, gdim)

    return refined(cached(comm, generator, params, make), refine)


def _mesh_options(gmsh, h: float, quadrilateral: bool) -> None:
    gmsh.option.setNumber("Mesh.CharacteristicLengthMax", h)
    gmsh.option.setNumber("Mesh.Algorithm", 8 if quadrilateral else 6)
    if quadrilateral:
        gmsh.option.setNumber("Mesh.RecombineAll", 1)
        gmsh.option.setNumber("Mesh.RecombinationAlgorithm", 2)


def _coarse(h: float, refine: int, quadrilateral: bool = False) -> float:
    """The cell size gmsh meshes at so that ``refine`` uniform refinements end at ``h``."""
    if quadrilateral and refine:
        raise ValueError(f"refine={refine}: uniform refinement splits triangles and tetrahedra only; mesh the "
                         "quadrilaterals at the cell size wanted (refine=0)")
    return float(h) * 2.0 ** check_refine(refine)


@timed("mesh_s")
def unstructured_rectangle(
    comm: MPI.Comm, h: float, *, size: tuple[float, float] = (1.0, 1.0), quadrilateral: bool = False, seed: int = 0,
    origin: tuple[float, float] = (0.0, 0.0), split_y: tuple[float, ...] = (), refine: int = 0,
) -> dolfinx.mesh.Mesh:
    """Frontal-Delaunay triangles (or recombined quadrilaterals) of size ``h`` on the rectangle
    ``origin + [0, size]``; mesh edges follow the horizontal lines ``y = split_y`` (so a
    constraint such as "fixed above y = 0" holds on a straight row of vertices). With
    ``refine`` K, gmsh meshes at ``h 2^K`` and every rank splits its cells K times
    (triangles only). Cached (:mod:`fempm.meshes.cache`). Collective."""
    (x0, y0), (w, hgt) = origin, size
    cuts = sorted(float(y) for y in split_y if y0 < y < y0 + hgt)
    coarse = _coarse(h, refine, quadrilateral)

    def build(gmsh):
        gmsh.model.add("rectangle")
        gmsh.option.setNumber("Mesh.RandomSeed", seed)
        edges = [y0, *cuts, y0 + hgt]
        parts = [(2, gmsh.model.occ.addRectangle(x0, a, 0, w, b - a)) for a, b in zip(edges[:-1], edges[1:])]
        if len(parts) > 1:
            parts, _ = gmsh.model.occ.fragment(parts[:1], parts[1:])
        gmsh.model.occ.synchronize()
        gmsh.model.addPhysicalGroup(2, [t for _, t in parts], 1)
        _mesh_options(gmsh, coarse, quadrilateral)
        gmsh.model.mesh.generate(2)

    params = {"h": coarse, "size": [float(v) for v in size], "origin": [float(v) for v in origin], "cuts": cuts,
              "quadrilateral": bool(quadrilateral), "seed": int(seed)}
    return _generated(comm, "rectangle", params, 2, build, refine).mesh


def unstructured_polygon(comm: MPI.Comm, vertices, h: float, *, seed: int = 0, refine: int = 0) -> dolfinx.mesh.Mesh:
    """Frontal-Delaunay triangles of size ``h`` on the polygon with ``vertices`` (k, 2), in order
    (``refine``: as :func:`tagged_polygon`'s)."""
    return tagged_polygon(comm, vertices, h, seed=seed, refine=refine).mesh


@timed("mesh_s")
def tagged_polygon(comm: MPI.Comm, vertices, h: float, edge_tags=None, *, quadrilateral: bool = False,
                   seed: int = 0, refine: int = 0):
    """Triangles (or recombined quadrilaterals) of size ``h`` on the polygon with ``vertices``
    (k, 2), in order, its edges tagged: ``edge_tags[i]`` (an int > 0, or 0 for none) the
    physical group of the edge from vertex i to vertex i + 1 (gmsh lines; the facets of the
    mesh that lie on it carry the tag, :func:`fempm.boundary.tagged`). With ``refine`` K, gmsh
    meshes at ``h 2^K`` and every rank splits its cells K times, the tags passed to the
    children (triangles only). Cached (:mod:`fempm.meshes.cache`). Returns DOLFINx
    ``MeshData`` (``mesh``, ``facet_tags``, ...). Collective."""
    k = len(vertices)
    tags = [0] * k if edge_tags is None else [int(t) for t in edge_tags]
    if len(tags) != k or any(t < 0 for t in tags):
        raise ValueError(f"edge_tags needs one tag >= 0 per edge ({k}), got {edge_tags!r}")
    vertices = [[float(x), float(y)] for x, y in vertices]
    coarse = _coarse(h, refine, quadrilateral)

    def build(gmsh):
        gmsh.model.add("polygon")
        gmsh.option.setNumber("Mesh.RandomSeed", seed)
        pts = [gmsh.model.occ.addPoint(x, y, 0.0) for x, y in vertices]
        lines = [gmsh.model.occ.addLine(a, b) for a, b in zip(pts, pts[1:] + pts[:1])]
        surface = gmsh.model.occ.addPlaneSurface([gmsh.model.occ.addCurveLoop(lines)])
        gmsh.model.occ.synchronize()
        gmsh.model.addPhysicalGroup(2, [surface], 1)
        for t in sorted(set(tags) - {0}):
            gmsh.model.addPhysicalGroup(1, [line for line, tag in zip(lines, tags) if tag == t], t)
        _mesh_options(gmsh, coarse, quadrilateral)
        gmsh.model.mesh.generate(2)

    params = {"h": coarse, "vertices": vertices, "tags": tags, "quadrilateral": bool(quadrilateral), "seed": int(seed)}
    return _generated(comm, "polygon", params, 2, build, refine)


@timed("mesh_s")
def unstructured_box(comm: MPI.Comm, h: float, *, size=(1.0, 1.0, 1.0), refine: int = 0) -> dolfinx.mesh.Mesh:
    """Delaunay tetrahedra of size ``h`` on a box (``refine``: gmsh at ``h 2^K``, then K uniform
    refinements on every rank). Cached (:mod:`fempm.meshes.cache`). Collective."""
    size = [float(v) for v in size]
    coarse = _coarse(h, refine)

    def build(gmsh):
        gmsh.model.add("box")
        v = gmsh.model.occ.addBox(0, 0, 0, *size)
        gmsh.model.occ.synchronize()
        gmsh.model.addPhysicalGroup(3, [v], 1)
        gmsh.option.setNumber("Mesh.CharacteristicLengthMax", coarse)
        gmsh.model.mesh.generate(3)

    return _generated(comm, "box", {"h": coarse, "size": size}, 3, build, refine).mesh
