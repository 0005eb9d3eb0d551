r"""A background mesh redistributed so that every rank holds about the same number of particles.

DOLFINx partitions a mesh by cells; MPM work per step goes with the particles, which usually
fill part of the mesh. :func:`particle_balanced` cuts space by weighted recursive coordinate
bisection (RCB): a box of cells for :math:`P` ranks is cut across its longest side at the
position :math:`s` where

.. math::
    w(s) = \#\{p : x_p < s\} + \omega\, \#\{c : \bar x_c < s\}
    = \frac{\lfloor P/2 \rfloor}{P} \left(\#\{p\} + \omega\, \#\{c\}\right)

(points :math:`x_p` and cell midpoints :math:`\bar x_c` in the box; :math:`\omega` the weight
of a cell's grid work against a particle's), found by bisection with one ``allreduce`` per
step over all boxes of a level; each half goes on with its share of the ranks. A cell goes to
the rank of the box holding its midpoint, and the mesh is built again from the same nodes and
cells with that partition (:func:`dolfinx.mesh.create_mesh`; mesh tags are not carried). The
pieces are boxes, so their boundaries stay short. Without ``ghosts`` a rank holds its own
cells only (the point step needs no more); with ``ghosts=True`` it also holds every cell that
shares a node with one of its own, as ghosts (particle domains reach into the cells around
their particle's: their compiled passes need those cells, :mod:`fempm.stepping.domain_grid`).
"""

from __future__ import annotations

import dolfinx.graph
import dolfinx.mesh
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.meshes.geometry import coordinate_map

__all__ = ["BISECTIONS", "node_ghosts", "particle_balanced", "rcb_parts"]

#: bisection steps of each cut (the cut is then within 2^-50 of the box's side)
BISECTIONS = 50


def rcb_parts(comm: MPI.Comm, points: npt.NDArray, centres: npt.NDArray, parts: int, cell_weight: float) -> npt.NDArray:
    """The part (0..parts-1) of each of this rank's ``centres`` (n, gdim) by weighted RCB of
    the ``points`` (m, gdim) of every rank and the centres (see the module). Collective."""
    items = np.concatenate([points, centres])
    weight = np.concatenate([np.ones(len(points)), np.full(len(centres), cell_weight)])
    ranges = [(0, parts)]  # the parts of each box, the same on every rank
    box = np.zeros(len(items), dtype=np.int64)
    while any(h - lo > 1 for lo, h in ranges):
        nb = len(ranges)
        low = np.full((nb, items.shape[1]), np.inf)
        high = np.full((nb, items.shape[1]), -np.inf)
        np.minimum.at(low, box, items)
        np.maximum.at(high, box, items)
        comm.Allreduce(MPI.IN_PLACE, low, op=MPI.MIN)
        comm.Allreduce(MPI.IN_PLACE, high, op=MPI.MAX)
        extent = np.where(np.isfinite(high - low), high - low, 0.0)
        axis = np.argmax(extent, axis=1)
        total = np.bincount(box, weights=weight, minlength=nb)
        comm.Allreduce(MPI.IN_PLACE, total, op=MPI.SUM)
        share = np.array([(h - lo) // 2 / (h - lo) for lo, h in ranges])
        a = np.where(np.isfinite(low[np.arange(nb), axis]), low[np.arange(nb), axis], 0.0)
        z = np.where(np.isfinite(high[np.arange(nb), axis]), high[np.arange(nb), axis], 0.0)
        coord = items[np.arange(len(items)), axis[box]]
        for _ in range(BISECTIONS):
            s = 0.5 * (a + z)
            left = np.bincount(box, weights=weight * (coord < s[box]), minlength=nb)
            comm.Allreduce(MPI.IN_PLACE, left, op=MPI.SUM)
            under = left < share * total
            a, z = np.where(under, s, a), np.where(under, z, s)
        below = coord < (0.5 * (a + z))[box]
        children, first = [], []
        for lo, h in ranges:  # a box of one part stays; the others split into two
            first.append(len(children))
            children += [(lo, h)] if h - lo == 1 else [(lo, lo + (h - lo) // 2), (lo + (h - lo) // 2, h)]
        split = np.array([h - lo > 1 for lo, h in ranges])
        box = np.asarray(first)[box] + (split[box] & ~below)
        ranges = children
    return np.array([lo for lo, _ in ranges])[box[len(points):]]


def node_ghosts(comm: MPI.Comm, nodes: npt.NDArray[np.int64], part: npt.NDArray[np.int32],
                num_nodes: int) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.int32]]:
    """The destinations of this rank's cells (global node indices ``nodes`` (cells, k),
    owners ``part``) with ghosts: each cell's owner first, then every other rank that owns a
    cell sharing one of its nodes (``num_nodes`` nodes in all), as (data, offsets) of an
    adjacency list. Each (node, rank) pair goes to the node's home rank, which sends back every
    rank that touches each node asked about. Collective."""
    size = comm.size
    k = nodes.shape[1]
    flat_nodes = nodes.ravel()
    flat_part = np.repeat(part, k).astype(np.int64)
    home = (flat_nodes * size // max(num_nodes, 1)).astype(np.int64)
    order = np.argsort(home, kind="stable")
    cuts = np.searchsorted(home[order], np.arange(size + 1))
    sent = [np.stack([flat_nodes[order[cuts[r]:cuts[r + 1]]], flat_part[order[cuts[r]:cuts[r + 1]]]], axis=1)
            for r in range(size)]
    got = comm.alltoall(sent)  # (node, rank) pairs of the nodes at home here
    pairs = np.unique(np.concatenate(got), axis=0)  # sorted by node, then rank
    answers = [pairs[np.isin(pairs[:, 0], g[:, 0])] for g in got]  # every rank at the nodes each sender asked
    known = np.unique(np.concatenate(comm.alltoall(answers)), axis=0)
    # (cell, rank) for every rank at every node of every cell
    first = np.searchsorted(known[:, 0], flat_nodes, side="left")
    count = np.searchsorted(known[:, 0], flat_nodes, side="right") - first
    cell = np.repeat(np.repeat(np.arange(len(nodes)), k), count)
    rank = known[np.repeat(first, count) + np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count), 1]
    ghost = np.unique(np.stack([cell, rank], axis=1)[rank != part[cell]], axis=0)
    # the owner first: the owner's key (cell, -1) sorts before the cell's ghost ranks
    key = np.concatenate([np.stack([np.arange(len(nodes)), np.full(len(nodes), -1)], axis=1), ghost])
    data = np.concatenate([part, ghost[:, 1]])[np.lexsort((key[:, 1], key[:, 0]))]
    offsets = np.concatenate([[0], np.cumsum(1 + np.bincount(ghost[:, 0], minlength=len(nodes)))])
    return data.astype(np.int32), offsets.astype(np.int32)


def particle_balanced(mesh: dolfinx.mesh.Mesh, points: npt.NDArray, *, cell_weight: float = 0.1,
                      ghosts: bool = False) -> dolfinx.mesh.Mesh:
    """The cells and nodes of ``mesh`` distributed again so that each rank owns about the same
    number of the ``points`` (n, gdim; the particle positions given on any rank) plus
    ``cell_weight`` times its number of cells (see the module); with ``ghosts`` every rank
    also holds the cells sharing a node with its own. Collective."""
    comm = mesh.comm
    if cell_weight < 0.0:
        raise ValueError(f"cell_weight must be non-negative, got {cell_weight}")
    gdim = mesh.geometry.dim
    points = np.asarray(points, dtype=np.float64).reshape(-1, gdim)
    tdim = mesh.topology.dim
    owned = mesh.topology.index_map(tdim).size_local
    dofmap = np.asarray(coordinate_map(mesh)[1])[:owned]
    x = mesh.geometry.x[:, :gdim]
    centres = x[dofmap].mean(axis=1)
    part = rcb_parts(comm, points, centres, comm.size, cell_weight).astype(np.int32)
    gmap = mesh.geometry.index_map()
    nodes = np.asarray(gmap.local_to_global(dofmap.ravel().astype(np.int32)), dtype=np.int64).reshape(dofmap.shape)
    coords = np.ascontiguousarray(x[: gmap.size_local])

    if ghosts and comm.size > 1:
        data, offsets = node_ghosts(comm, nodes, part, gmap.size_global)
    else:
        data, offsets = part, np.arange(len(part) + 1, dtype=np.int32)

    def partitioner(comm_, nparts, cell_types, cells):
        return dolfinx.graph.adjacencylist(data, offsets)._cpp_object

    return dolfinx.mesh.create_mesh(comm, nodes, mesh.ufl_domain().ufl_coordinate_element(), coords, partitioner)
