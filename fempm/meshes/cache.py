"""A cache of the meshes gmsh makes: made once, read in parallel every time after.

gmsh meshes on rank 0 alone (a million triangles take minutes, and more ranks do not help);
DOLFINx reads an XDMF mesh on every rank at once in a fraction of that. A generated mesh
(:mod:`fempm.meshes.generators`) is written once to ``<folder>/<generator>-<key>/mesh.xdmf``
(with its cell and facet tags and physical groups), the key a hash of the generator's name,
its parameters, gmsh's version and the cache's format; every run, the first included, reads
the mesh from there, so a run that made the mesh and one that read it compute on the same
mesh, cell for cell, on any number of ranks.

The folder: :func:`set_mesh_cache` (the command line's ``--mesh-cache DIR``,
``--no-mesh-cache``), else the environment variable ``FEMPM_CACHE``, else
``$XDG_CACHE_HOME/fempm`` (``~/.cache/fempm``). ``FEMPM_CACHE=off`` (or ``none``) turns the
cache off. An entry is written to a temporary folder and renamed into place, so concurrent
runs that make the same mesh do not see half an entry; entries are never evicted (delete the
folder to empty it).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import uuid
from collections.abc import Callable
from pathlib import Path

import dolfinx.io
import dolfinx.mesh
import numpy as np
from mpi4py import MPI

__all__ = ["CACHE_ENV", "FORMAT", "cached", "mesh_cache", "set_mesh_cache"]

#: the environment variable naming the cache folder (``off`` or ``none``: no cache)
CACHE_ENV = "FEMPM_CACHE"
#: the entries' format; a new one makes new keys
FORMAT = 1
_OFF = ("off", "none", "0", "")
_DEFAULT = object()
_chosen: list = [_DEFAULT]


def set_mesh_cache(folder: str | Path | None = _DEFAULT) -> None:  # type: ignore[assignment]
    """Cache generated meshes in ``folder`` (None: no cache; no argument: back to the
    environment's or the default folder, :func:`mesh_cache`)."""
    _chosen[0] = folder if folder is None or folder is _DEFAULT else Path(folder)


def mesh_cache() -> Path | None:
    """The cache folder in use (None: the cache is off)."""
    if _chosen[0] is not _DEFAULT:
        return _chosen[0]
    env = os.environ.get(CACHE_ENV)
    if env is not None:
        return None if env.strip().lower() in _OFF else Path(env)
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "fempm"


def _key(generator: str, params: dict) -> str:
    import gmsh

    text = json.dumps({"generator": generator, "params": params, "gmsh": gmsh.__version__, "format": FORMAT},
                      sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def cached(comm: MPI.Comm, generator: str, params: dict, make: Callable[[], dolfinx.io.gmsh.MeshData]
           ) -> dolfinx.io.gmsh.MeshData:
    """The mesh ``make()`` builds (collective, DOLFINx ``MeshData``), from the cache when an
    entry for ``generator`` and ``params`` is there, else made, written and read back.

    Args:
        comm: The mesh's communicator.
        generator: The generator's name (the entry's folder's prefix).
        params: Everything the mesh depends on (JSON-able), with ``generator`` the key.
        make: Builds the mesh (gmsh on rank 0, distributed).

    Note:
        Collective. Without a cache folder (:func:`mesh_cache` None) this is ``make()``.
    """
    folder = comm.bcast(mesh_cache() if comm.rank == 0 else None, root=0)  # rank 0's, wherever the others look
    if folder is None:
        return make()
    entry = folder / f"{generator}-{_key(generator, params)}"
    if not comm.bcast((entry / "physical_groups.json").is_file() if comm.rank == 0 else None, root=0):
        _write(comm, entry, make(), {"generator": generator, "params": params})
    return _read(comm, entry)


def _write(comm: MPI.Comm, entry: Path, data, meta: dict) -> None:
    """Write ``data`` to a temporary folder, then rename it to ``entry`` (collective)."""
    tmp = entry.with_name(f"{entry.name}.tmp-{comm.bcast(uuid.uuid4().hex if comm.rank == 0 else None, root=0)}")
    if comm.rank == 0:
        tmp.mkdir(parents=True, exist_ok=True)
    comm.barrier()
    mesh = data.mesh
    mesh.name = "mesh"
    uniform = _uniform(comm, mesh, data.cell_tags)
    with dolfinx.io.XDMFFile(comm, tmp / "mesh.xdmf", "w") as f:
        f.write_mesh(mesh)
        for name, tags in (("cell_tags", data.cell_tags), ("facet_tags", data.facet_tags)):
            if tags is not None and not (name == "cell_tags" and uniform is not None):
                tags.name = name
                f.write_meshtags(tags, mesh.geometry)
    if comm.rank == 0:
        groups = {name: [int(g.dim), int(g.tag)] for name, g in data.physical_groups.items()}
        tags = [name for name, t in (("cell_tags", data.cell_tags), ("facet_tags", data.facet_tags)) if t is not None]
        (tmp / "physical_groups.json").write_text(json.dumps({**meta, "groups": groups, "tags": tags,
                                                              "uniform_cell_tag": uniform}, default=repr))
        try:
            tmp.rename(entry)
        except OSError:  # another run wrote the same entry meanwhile
            shutil.rmtree(tmp, ignore_errors=True)
    comm.barrier()


def _uniform(comm: MPI.Comm, mesh, tags) -> int | None:
    """The one value of cell tags that tag every cell alike (the usual single physical group:
    rebuilt on reading instead of read, which takes as long as the mesh), else None."""
    if tags is None:
        return None
    num = mesh.topology.index_map(mesh.topology.dim).size_local
    values = np.unique(tags.values[tags.indices < num])
    every = comm.allreduce(int(np.count_nonzero(tags.indices < num))) == comm.allreduce(num)
    found = comm.allgather(values.tolist())
    distinct = set(v for part in found for v in part)
    return int(distinct.pop()) if every and len(distinct) == 1 else None


def _read(comm: MPI.Comm, entry: Path) -> dolfinx.io.gmsh.MeshData:
    """The mesh of a cache entry, distributed over ``comm`` without ghost cells (as gmsh's)."""
    meta = json.loads((entry / "physical_groups.json").read_text())
    with dolfinx.io.XDMFFile(comm, entry / "mesh.xdmf", "r") as f:
        mesh = f.read_mesh(ghost_mode=dolfinx.mesh.GhostMode.none, name="mesh")
        tdim = mesh.topology.dim
        if "facet_tags" in meta["tags"]:
            mesh.topology.create_connectivity(tdim - 1, tdim)
        uniform = meta.get("uniform_cell_tag")
        tags = {name: f.read_meshtags(mesh, name) for name in meta["tags"]
                if not (name == "cell_tags" and uniform is not None)}
    if uniform is not None and "cell_tags" in meta["tags"]:
        num = mesh.topology.index_map(tdim).size_local + mesh.topology.index_map(tdim).num_ghosts
        tags["cell_tags"] = dolfinx.mesh.meshtags(mesh, tdim, np.arange(num, dtype=np.int32),
                                                  np.full(num, uniform, dtype=np.int32))
        tags["cell_tags"].name = "cell_tags"
    groups = {name: dolfinx.io.gmsh.PhysicalGroup(dim, tag) for name, (dim, tag) in meta["groups"].items()}
    return dolfinx.io.gmsh.MeshData(mesh, tags.get("cell_tags"), tags.get("facet_tags"), None, None, groups)
