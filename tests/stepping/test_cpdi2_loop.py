"""CPDI2 in the explicit loop, on 1 and 2 ranks: corners move with the grid velocity, the
particle sits at its domain's centroid and has its volume.

* An affine velocity field is projected exactly (consistent mass), so one step moves every
  corner by exactly :math:`\\Delta t (A y + b)` and gives :math:`F = I + \\Delta t A`.
* Over many steps of a deforming elastic body the particle domains stay a conforming tiling
  (corners shared at the start stay shared), simplex domains keep :math:`F E_0 = E` and
  :math:`|\\Omega_p| = J V_p^0`, momentum is conserved to round-off, and 2 ranks = 1 rank.
"""

import dolfinx.fem as fem
import dolfinx.mesh as dm
import fempm
import numpy as np
import pytest
import ufl
from conftest import make_mesh
from mpi4py import MPI

from fempm.transfer.domains import domain_geometry
from fempm.materials import LinearElastic, NeoHookean
from fempm.meshes import unstructured_rectangle
from fempm.stepping import ExplicitSolver, StepOptions

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD
AFFINE = {2: (np.array([[0.3, -0.5], [0.4, 0.2]]), np.array([0.2, -0.1])),
          3: (np.array([[0.3, -0.5, 0.1], [0.4, 0.2, -0.2], [0.0, 0.3, -0.1]]), np.array([0.2, -0.1, 0.05]))}


@pytest.mark.parametrize("name", ["triangle", "quadrilateral", "unstructured-triangle",
                                  *(pytest.param(c, marks=pytest.mark.slow) for c in ("tetrahedron", "hexahedron"))])
# (3D: 15-16 s each, in make test-all)
def test_affine_velocity_moves_corners_exactly(name):
    mesh = make_mesh(name)
    d = mesh.geometry.dim
    A, B = AFFINE[d]
    p = fempm.create_particles(mesh, 2**d, density=3.0, corners=True)
    p.fields["start"] = p.fields["corners"].copy()
    p.fields["v"] = p.x @ A.T + B
    V = fem.functionspace(mesh, ("Lagrange", 1, (d,)))
    opts = StepOptions(mass="consistent", flip=0.0, lump_below=0.0, domain="cpdi2")
    solver = ExplicitSolver(V, p, [LinearElastic(1.0, 0.3)], options=opts)
    dt = 1e-2
    solver.step(dt)  # no stress yet: the grid velocity is the projected affine field
    c, c_start = p.fields["corners"], p.fields["start"]  # "start" travelled with migrating particles
    F = p.fields["F"]
    errs = [
        np.abs(c - (c_start + dt * (c_start @ A.T + B))).max(initial=0.0),
        np.abs(F - (np.eye(d) + dt * A)).max(initial=0.0),
        np.abs(p.volume - np.linalg.det(np.eye(d) + dt * A) * p.fields["volume0"]).max(initial=0.0),
        np.abs(p.x - domain_geometry(c)[3]).max(initial=0.0) if len(c) else 0.0,
    ]
    errs = np.array(errs)
    comm.Allreduce(MPI.IN_PLACE, errs, op=MPI.MAX)
    assert errs.max() < 1e-10, errs  # measured 1e-15 (KSP rtol 1e-13 on the projection)
    area = comm.allreduce(fem.assemble_scalar(fem.form(fem.Constant(mesh, 1.0) * ufl.dx(domain=mesh))))
    assert comm.allreduce(float(p.fields["volume0"].sum())) == pytest.approx(area, rel=1e-13)  # a tiling


def deform(mesh, steps=40):
    """A block of sub-cell particles, swirled and stretched, neo-Hookean, no constraints."""
    p = fempm.create_particles(
        mesh, 4, density=1.0, corners=True,
        cells=lambda x: (np.abs(x[0] - 0.5) < 0.25) & (np.abs(x[1] - 0.5) < 0.25),
    )
    p.fields["start"] = p.fields["corners"].copy()  # travels with the particles
    x = p.x - 0.5
    p.fields["v"] = np.column_stack([-x[:, 1] + 0.5 * x[:, 0] ** 2, x[:, 0] + 0.8 * x[:, 1]]) * 2.0
    V = fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    solver = ExplicitSolver(V, p, [NeoHookean(50.0, 0.3)], options=StepOptions(domain="cpdi2", flip=1.0))
    mom0 = solver.energies()
    for _ in range(steps):
        solver.step()
    return p, solver, mom0


def gathered(p, key):
    ids = np.concatenate(p.comm.allgather(p.ids))
    vals = np.concatenate(p.comm.allgather(key(p)))
    return vals[np.argsort(ids)]


BLOCK_MESHES = {
    "unstructured-triangle": lambda c: unstructured_rectangle(c, 1 / 12),
    "quadrilateral": lambda c: dm.create_unit_square(c, 12, 12, dm.CellType.quadrilateral),
}


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n == "quadrilateral" else n
                                  for n in sorted(BLOCK_MESHES)])  # (quadrilaterals: make test-all)
def test_cpdi2_domains_stay_conforming(name):
    world = BLOCK_MESHES[name](comm)
    p, solver, e0 = deform(world)
    e1 = solver.energies()
    for k in ("momentum_x", "momentum_y"):  # lumped mass, no constraints: exact to round-off
        assert abs(e1[k] - e0[k]) < 1e-13, (k, e0[k], e1[k])
    corners = gathered(p, lambda q: q.fields["corners"])
    c0 = gathered(p, lambda q: q.fields["start"])
    # corners that coincide at the start still coincide: the domains tile the deformed body
    key = np.round(c0.reshape(-1, 2) * 1e6).astype(np.int64)
    _, group = np.unique(key, axis=0, return_inverse=True)
    flat = corners.reshape(-1, 2)
    spread = max(np.ptp(flat[group.ravel() == gi], axis=0).max() for gi in np.unique(group))
    assert spread < 1e-12, spread
    moved = np.abs(corners - c0).max()
    assert moved > 0.05  # the body did deform (measured 0.14)
    vol = gathered(p, lambda q: q.volume)
    np.testing.assert_allclose(vol, domain_geometry(corners)[2], rtol=1e-12)
    if corners.shape[1] == 3:  # simplices: F maps the initial edges to the current ones, |Omega| = J V0
        F = gathered(p, lambda q: q.fields["F"])
        E0 = np.swapaxes(c0[:, 1:] - c0[:, :1], 1, 2)
        E = np.swapaxes(corners[:, 1:] - corners[:, :1], 1, 2)
        assert np.abs(F @ E0 - E).max() < 1e-12
        V0 = gathered(p, lambda q: q.fields["volume0"])
        np.testing.assert_allclose(vol, np.linalg.det(F) * V0, rtol=1e-10)
    if comm.size > 1:  # 2 ranks = 1 rank
        serial, _, _ = deform(BLOCK_MESHES[name](MPI.COMM_SELF))
        s = serial.fields["corners"][np.argsort(serial.ids)]
        np.testing.assert_allclose(corners, s, rtol=0, atol=1e-12)
