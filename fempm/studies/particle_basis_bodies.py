"""The bodies of the particle-basis study (:mod:`fempm.studies.particle_basis`): particles on
a line, on a quadrilateral grid and on unstructured triangles, with their dense operators."""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Callable

import dolfinx
import dolfinx.mesh as dm
import numpy as np
from mpi4py import MPI

from fempm.meshes.generators import unstructured_rectangle
from fempm.particles.corners import box_corners
from fempm.particles.particle_set import Particles
from fempm.transfer.domains import CPDI1, CPDI2, GIMP, Point
from fempm.transfer.particle_basis import (
    dense_operator,
    partially_lumped_psi,
    psi,
)

__all__ = [
    "ALG_TOL", "COMM", "DENSITIES", "DOMAINS", "OPTIONS", "OPTION_NAMES", "TOL", "Body", "body", "line_body",
    "line_mesh", "quad_body", "quad_mesh", "tri_body", "tri_mesh",
]

COMM = MPI.COMM_SELF
OPTIONS = ("lumped", "consistent", "partial")
DOMAINS = {"point": Point(), "gimp": GIMP(order=4, deform=True), "cpdi1": CPDI1(), "cpdi2": CPDI2()}
DENSITIES = (4, 2, 1, 0.5)  # particles per cell (and per direction in 2D)
TOL = 1e-12  # round-off
ALG_TOL = 1e-8  # identities through a (possibly ill-conditioned) inverse: round-off times its condition
OPTION_NAMES = {"lumped": "option 1", "consistent": "option 2",
                "partial": "option 2 with dofs below 10 % of the largest lumped mass lumped, as in the explicit loop"}


@dataclass
class Body:
    """A body of particles on a background mesh with its dense operators."""

    mesh: dm.Mesh
    V: dolfinx.fem.FunctionSpace
    particles: Particles
    x: np.ndarray  # particle positions in id order
    S: np.ndarray  # <N_i>_p, (n, ndofs)
    xd: np.ndarray  # dof coordinates (ndofs, d)
    lo: np.ndarray
    hi: np.ndarray  # the body's box
    h: float
    spacing: float

    def psi(self, option: str) -> np.ndarray:
        """psi of option 1 ("lumped"), option 2 ("consistent") or option 2 with the rows and
        columns of dofs below 10 % of the largest lumped mass lumped ("partial", the explicit
        loop's default ``lump_below=0.1``)."""
        mass = self.particles.mass[np.argsort(self.particles.ids)]  # id order, as the rows of S
        if option != "partial":
            return psi(self.S, mass, option)
        return partially_lumped_psi(self.S, mass, 0.1)

    def at(self, pts: np.ndarray) -> np.ndarray:
        """Dense point-evaluation operator of the grid basis at ``pts`` (m, ndofs)."""
        return dense_operator(self.V, Particles(self.mesh, pts, 1.0, 1.0))


def line_mesh(h: float, length: float = 10.0) -> dm.Mesh:
    return dm.create_interval(COMM, int(round(length / h)), [0.0, length])


def quad_mesh(h: float, length: float = 8.0) -> dm.Mesh:
    n = int(round(length / h))
    return dm.create_rectangle(COMM, [[0.0, 0.0], [length, length]], [n, n], dm.CellType.quadrilateral)


def tri_mesh(h: float = 1.0, length: float = 8.0) -> dm.Mesh:
    return unstructured_rectangle(COMM, h, size=(length, length), seed=1)


def _moved(m: dm.Mesh, A, shift) -> dm.Mesh:
    """The mesh mapped by x -> c + A (x - c) + shift (c the centre of its box)."""
    if A is None and shift is None:
        return m
    d = m.geometry.dim
    x = m.geometry.x[:, :d]
    c = 0.5 * (x.min(axis=0) + x.max(axis=0))
    A = np.eye(d) if A is None else np.atleast_2d(A)
    shift = np.zeros(d) if shift is None else np.atleast_1d(shift)
    m.geometry.x[:, :d] = c + (x - c) @ A.T + shift
    return m


def body(make_mesh: Callable, density: float, domain, *, lo, hi, offset=0.0, shift=0.0, A=None,
         grid_moves=False) -> Body:
    """Lattice particles filling the box [lo, hi] + ``offset`` (``density`` per cell and
    direction; below 1 the grid is refined so that the particles keep the size of the
    1-per-cell case), then moved by x -> c + A (x - c) + shift with F = A (c the centre of the
    mesh); with ``grid_moves`` the mesh moves the same way."""
    h = 1.0 if density >= 1 else 0.5
    spacing = h / density
    lo, hi = np.atleast_1d(np.asarray(lo, float)), np.atleast_1d(np.asarray(hi, float))
    d = len(lo)
    A = np.eye(d) if A is None else np.atleast_2d(np.asarray(A, float))
    shift = np.broadcast_to(np.asarray(shift, float), (d,))
    axes = [np.arange(a + spacing / 2, b, spacing) for a, b in zip(lo, hi)]
    x0 = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, d) + offset
    mesh = make_mesh(h)
    cm = 0.5 * (mesh.geometry.x[:, :d].min(axis=0) + mesh.geometry.x[:, :d].max(axis=0))
    if grid_moves:
        _moved(mesh, A, shift)
    x = cm + (x0 - cm) @ A.T + shift
    corners = cm + (box_corners(x0, np.full((len(x0), d), spacing / 2)) - cm) @ A.T + shift  # CPDI2: lattice cells
    vol0 = spacing**d
    p = Particles(mesh, x, vol0, vol0 * abs(np.linalg.det(A)), fields={
        "lp": np.full((len(x), d), spacing / 2), "F": np.broadcast_to(A, (len(x), d, d)).copy(), "corners": corners})
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    S = dense_operator(V, p, domain)
    return Body(mesh, V, p, x, S, V.tabulate_dof_coordinates()[:, :d], lo + offset, hi + offset, h, spacing)


def line_body(density: float, domain, *, length: float = 10.0, **kw) -> Body:
    """Particles on [3, length - 3] of a line of ``length`` cells."""
    return body(lambda h: line_mesh(h, length), density, domain, lo=[3.0], hi=[length - 3.0], **kw)


def quad_body(density: float, domain, **kw) -> Body:
    return body(quad_mesh, density, domain, lo=[2.0, 2.0], hi=[6.0, 6.0], **kw)


def tri_body(domain, *, length: float = 8.0, **kw) -> Body:
    """2 x 2 particles per unit cell on [2, length - 2]^2 of an unstructured triangle mesh."""
    return body(lambda h: tri_mesh(h, length), 2, domain, lo=[2.0, 2.0], hi=[length - 2.0] * 2, **kw)
