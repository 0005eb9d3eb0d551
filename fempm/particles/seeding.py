r"""Seed particles in every owned cell with a regular per-cell pattern.

The reference cell is split into ``ppc = n^d`` sub-cells of equal reference volume: a tensor
grid of boxes for intervals, quadrilaterals and hexahedra, and the Freudenthal (Kuhn)
subdivision for triangles and tetrahedra (the simplex :math:`1 \ge a_1 \ge \dots \ge a_d \ge 0`
cut by the grid of :math:`n^d` sub-cubes holds exactly :math:`n^d` equal sub-simplices).
A particle sits at the centroid of its sub-cell, moved with ``jitter`` in [0, 1] towards a
uniformly random point of the sub-cell (so it never leaves it). The random numbers are a hash
of (seed, original cell index, particle number): the particle set does not depend on the
number of ranks.

Particle volume: :math:`V_p = V_c\, w_p |\det J(X_p)| / \sum_{q \in c} w_q |\det J(X_q)|`
(``V_c / ppc`` on affine cells), mass :math:`M_p = \rho V_p`.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import dolfinx
import numpy as np
import numpy.typing as npt

from fempm.particles.corners import box_corners, domain_geometry
from fempm.particles.location import CellLocator, as_points3
from fempm.particles.particle_set import Particles
from fempm.timings import timed

__all__ = ["create_particles", "hashed_uniform", "per_direction", "reference_pattern"]

_TDIM = {"interval": 1, "triangle": 2, "quadrilateral": 2, "tetrahedron": 3, "hexahedron": 3}


def per_direction(ppc: int, d: int) -> int:
    """The particles per cell and direction of ``ppc`` particles per cell seeded as a lattice
    in ``d`` dimensions; a ValueError unless ``ppc`` is a ``d``-th power. Every scene's ``ppc``
    (and the command line's ``--ppc``) counts the particles per cell, as
    :func:`create_particles` does."""
    n = int(round(ppc ** (1.0 / d)))
    if ppc < 1 or n**d != ppc:
        ok = ", ".join(str(k**d) for k in range(1, 6))
        shape = {1: "a count", 2: "a square", 3: "a cube"}[d]
        raise ValueError(f"ppc={ppc} particles per cell must be {shape} for the per-cell lattice in {d}D "
                         f"({ok}, ...)")
    return n


def reference_pattern(cell_name: str, ppc: int) -> npt.NDArray:
    """Sub-cells of the reference cell: vertex coordinates, shape (ppc, nverts, tdim).

    Boxes give their lower and upper corners (nverts = 2); simplices their d + 1 vertices.
    """
    d = _TDIM[cell_name]
    n = per_direction(ppc, d)
    grid = np.array(list(itertools.product(range(n), repeat=d)), dtype=float)  # (n^d, d)
    if cell_name in ("interval", "quadrilateral", "hexahedron"):
        return np.stack([grid / n, (grid + 1) / n], axis=1)
    # Kuhn simplices of each sub-cube: vertices base + cumulative unit steps along a permutation
    subs = []
    for perm in itertools.permutations(range(d)):
        steps = np.zeros((d + 1, d))
        for k, axis in enumerate(perm):
            steps[k + 1 :, axis] += 1.0
        subs.append((grid[:, None, :] + steps[None]) / n)
    subs = np.concatenate(subs)  # (n^d d!, d+1, d) in the cube coordinates a
    a = subs.mean(axis=1)
    inside = np.all(np.diff(a, axis=1) < 0, axis=1)  # a_1 > a_2 > ... > a_d
    subs = subs[inside]
    # map the Kuhn simplex 1 >= a_1 >= ... >= a_d >= 0 to the reference simplex
    ref = subs.copy()
    ref[..., :-1] = subs[..., :-1] - subs[..., 1:]
    order = np.lexsort(ref.mean(axis=1).T[::-1])
    return ref[order]


def _splitmix64(z: npt.NDArray[np.uint64]) -> npt.NDArray[np.uint64]:
    with np.errstate(over="ignore"):
        z = z + np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return z ^ (z >> np.uint64(31))


def hashed_uniform(seed: int, keys: npt.NDArray[np.int64], k: int) -> npt.NDArray:
    """Uniform numbers in (0, 1), shape (len(keys), k), a pure function of (seed, key, j)."""
    base = _splitmix64(np.uint64(seed & 0xFFFFFFFFFFFFFFFF) + keys.astype(np.uint64))
    z = _splitmix64(base[:, None] + np.arange(1, k + 1, dtype=np.uint64)[None, :] * np.uint64(0x632BE59BD9B4E019))
    return ((z >> np.uint64(11)).astype(np.float64) + 0.5) / float(1 << 53)


@timed("particles_s")
def create_particles(
    mesh: dolfinx.mesh.Mesh,
    ppc: int,
    *,
    density: float | Callable[[npt.NDArray], npt.NDArray] = 1.0,
    jitter: float = 0.0,
    seed: int | None = None,
    cells: npt.NDArray[np.int32] | Callable[[npt.NDArray], npt.NDArray] | None = None,
    where: Callable[[npt.NDArray], npt.NDArray] | None = None,
    locator: CellLocator | None = None,
    corners: bool = False,
) -> Particles:
    """Seed ``ppc`` particles in every owned cell of ``mesh``.

    The reference cell is split into ``ppc`` sub-cells (``ppc`` a square in 2D, a cube in 3D:
    n per direction), and a particle sits at each sub-cell's centre mapped to the cell, with
    the sub-cell's share of the cell's volume.

    Args:
        mesh: The background mesh.
        ppc: Particles per cell.
        density: A number or a function of the positions (n, gdim) -> (n,); each particle's
            mass is its density times its volume.
        jitter: Random offset of each particle within its sub-cell, as a fraction of its size.
        seed: The random seed of the jitter.
        cells: Restrict the seeding to some owned cells: local cell indices, or a predicate on
            the cell midpoints (x of shape (3, n), as ``dolfinx.mesh.locate_entities``).
        where: Keep only the particles whose positions (3, n) satisfy it (a body's shape).
        locator: A :class:`fempm.particles.location.CellLocator` of ``mesh`` to reuse.
        corners: Make each particle its sub-cell, for CPDI2
            (:class:`fempm.transfer.domains.CPDI2`): ``fields["corners"]`` holds the sub-cell's
            vertices (simplices on simplex cells, quadrilaterals/hexahedra in
            :func:`fempm.transfer.domains.box_corners` order on tensor cells), and the
            particle's position and volume are its domain's centroid and volume.

    Returns:
        The particles (masses and volumes; ``fields["corners"]`` with ``corners``).

    Raises:
        ValueError: ``ppc`` not a ``d``-th power, ``jitter`` outside [0, 1], ``cells`` not owned
            cells or a predicate of the wrong shape.

    Note:
        Collective.
    """
    if not 0.0 <= jitter <= 1.0:
        raise ValueError(f"jitter={jitter} must lie in [0, 1]")
    if corners and jitter > 0.0:
        raise ValueError("corners=True needs jitter=0: a particle with corners sits at its domain's centroid")
    locator = locator if locator is not None else CellLocator(mesh)
    geom = locator.geometry
    comm = mesh.comm
    subs = reference_pattern(geom.cell_name, ppc)  # (ppc, nv, tdim)
    ncell = geom.num_owned
    chosen = np.arange(ncell, dtype=np.int32)
    if callable(cells):
        mid = dolfinx.mesh.compute_midpoints(mesh, geom.tdim, chosen)
        keep = np.asarray(cells(mid.T), dtype=bool)
        if keep.shape != (ncell,):
            raise ValueError(f"cells(x) must return one boolean per cell: x holds the {ncell} cell midpoints as "
                             f"columns, shape (3, {ncell}) (DOLFINx's convention), and it returned shape {keep.shape}")
        chosen = chosen[keep]
    elif cells is not None:
        chosen = np.asarray(cells, dtype=np.int32)
        if np.any((chosen < 0) | (chosen >= ncell)):
            raise ValueError("cells must be owned local cell indices")
    cells = np.repeat(chosen, ppc)
    local = np.tile(np.arange(ppc), len(chosen))
    ids = np.asarray(mesh.topology.original_cell_index[:ncell], dtype=np.int64)[cells] * ppc + local
    if subs.shape[1] == 2:  # boxes
        centre = subs.mean(axis=1)
        sample_of = lambda u: subs[local, 0] + u * (subs[local, 1] - subs[local, 0])  # noqa: E731
        nrand = geom.tdim
    else:  # simplices: Dirichlet(1) barycentric weights give a uniform point
        centre = subs.mean(axis=1)

        def sample_of(u):
            b = -np.log(u)
            b /= b.sum(axis=1, keepdims=True)
            return np.einsum("nv,nvt->nt", b, subs[local])

        nrand = geom.tdim + 1
    X = centre[local]
    if jitter > 0.0:
        if seed is None:
            seed = comm.bcast(int(np.random.SeedSequence().entropy % (1 << 63)), root=0)
        X = (1.0 - jitter) * X + jitter * sample_of(hashed_uniform(seed, ids, nrand))
    x = geom.push_forward(cells, X)
    w = np.abs(geom.detJ(cells, X))
    wsum = np.bincount(cells, weights=w, minlength=ncell)
    volume = geom.cell_volumes()[cells] * w / wsum[cells]
    fields = {}
    if corners:
        fields["corners"], x, X, volume = _sub_cell_domains(geom, subs, cells, local)
    if where is not None:
        keep = np.asarray(where(as_points3(x).T), dtype=bool)
        x, cells, X, volume, ids = x[keep], cells[keep], X[keep], volume[keep], ids[keep]
        fields = {k: v[keep] for k, v in fields.items()}
    rho = density(x) if callable(density) else np.full(len(x), float(density))
    return Particles.from_located(locator, x, cells, X, rho * volume, volume, ids, fields=fields)


def _sub_cell_domains(geom, subs: npt.NDArray, cells: npt.NDArray[np.int32], local: npt.NDArray):
    """Physical corners (n, k, gdim) of the particles' sub-cells, with their centroids,
    reference coordinates and volumes (:func:`fempm.transfer.domains.domain_geometry`)."""
    tdim = subs.shape[2]
    if subs.shape[1] == 2:  # boxes: lower/upper -> 2^d corners
        ref = box_corners(subs.mean(axis=1), (subs[:, 1] - subs[:, 0]) / 2.0)
    else:
        ref = subs
    k = ref.shape[1]
    C = geom.push_forward(np.repeat(cells, k), ref[local].reshape(-1, tdim)).reshape(len(cells), k, tdim)
    _, _, volume, x = domain_geometry(C)
    return C, x, geom.pull_back(cells, x), volume
