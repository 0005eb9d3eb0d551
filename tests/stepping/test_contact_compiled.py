"""Multi-field contact in compiled passes (fempm.stepping.contact_points) against the numpy
contact step (fempm.stepping.contact.ContactGrid), its reference.

Two bodies pressed into each other from the start (every step corrects nodes where both have
mass), on every cell type of the compiled passes, 1 and 2 ranks: positions, velocities,
deformation gradients, stresses, the steps and the grid velocity agree to round-off, with and
without friction and the contact gap, with a rigid body (whose particles keep their velocity in
the same passes), USL and MUSL, axis-aligned walls (the fused grid update) and walls that check
contact by position (the numpy grid stages on the grouped arrays); with lumped and with consistent
mass (a matrix per body).
"""

import dolfinx.fem
import dolfinx.mesh as dm
import numpy as np
import pytest
from mpi4py import MPI

import fempm
from fempm.boundary import fixed, friction, slip
from fempm.materials import LinearElastic, NeoHookean
from fempm.stepping import ExplicitSolver, Loads, StepOptions
from fempm.stepping.contact import Contact, ContactGrid
from fempm.stepping.contact_points import ContactPointGrid
from tests.matrix import covering

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD

MESHES = {
    "interval": lambda: dm.create_unit_interval(comm, 30),
    "triangle": lambda: dm.create_unit_square(comm, 12, 11),
    "quadrilateral": lambda: dm.create_unit_square(comm, 12, 11, dm.CellType.quadrilateral),
    "tetrahedron": lambda: dm.create_unit_cube(comm, 5, 4, 5),
    "hexahedron": lambda: dm.create_unit_cube(comm, 5, 5, 4, dm.CellType.hexahedron),
}


def make_solver(cell: str, options: StepOptions, contact: Contact, walls: str, compiled=None) -> ExplicitSolver:
    """Two bodies in |x - 0.5| < 0.3, split at x_0 = 0.5, moving into each other at 0.6 (with a
    per-particle swirl), on a space of degree 1; ``walls``: "axis" (slip and fixed walls) or
    "position" (and a frictional wall with a gap, which checks contact by position)."""
    mesh = MESHES[cell]()
    d = mesh.geometry.dim
    p = fempm.create_particles(mesh, 2 ** d, density=1.0, jitter=0.3, seed=3,
                               where=lambda x: np.all(np.abs(x[:d] - 0.5) < 0.3, axis=0))
    right = p.x[:, 0] > 0.5
    p.fields["group"] = right.astype(np.int32)
    p.fields["body"] = right.astype(np.int32)
    p.fields["v"] = np.where(right, -0.6, 0.6)[:, None] * np.eye(d)[0] + 0.2 * np.sin(5.0 * p.x[:, ::-1])
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (d,)))
    bcs = [slip(V, lambda x: x[0] < 0.15, np.eye(d)[0]), fixed(V, lambda x: x[0] > 0.9)]
    if walls == "position" and d > 1:
        bcs.append(friction(V, lambda x: x[1] < 0.22, -np.eye(d)[1], 0.3, gap=0.05))
    return ExplicitSolver(V, p, [NeoHookean(50.0, 0.3), LinearElastic(40.0, 0.25)], bcs=bcs,
                          loads=Loads(body_force=-np.eye(d)[d - 1]), options=options, contact=contact,
                          compiled=compiled)


def state(solver):
    """The particles' state on every rank in the order of their ids, and the grid velocity's
    largest entry."""
    p = solver.particles
    order = np.argsort(np.concatenate(comm.allgather(p.ids)))
    arrays = [np.concatenate(comm.allgather(a))[order] for a in (p.x, p.fields["v"], p.fields["F"],
                                                                   p.fields["sigma"], p.volume)]
    return arrays + [comm.allreduce(float(np.abs(solver.grid_velocity).max(initial=0.0)), op=MPI.MAX)]


@pytest.mark.parametrize(("cell", "scheme", "kind"), covering(
    list(MESHES), ["USL", "MUSL"], ["slip", "friction", "friction and gap", "friction, gap and walls by position",
                                    "rigid", "rigid, friction and gap"]))
def test_compiled_contact_equals_the_numpy_contact_step(cell, scheme, kind):
    mu = 0.0 if kind in ("slip", "rigid") else 0.4
    contact = Contact(field="group", friction=mu, gap=0.04 if "gap" in kind else None,
                      rigid=(1,) if "rigid" in kind else ())
    walls = "position" if "position" in kind else "axis"
    out = []
    for compiled in (False, None):
        solver = make_solver(cell, StepOptions(scheme=scheme, flip=0.95, damping=0.3), contact, walls, compiled)
        dts = [solver.step() for _ in range(12)]
        grid = solver.grid
        assert isinstance(grid, ContactGrid if compiled is False else ContactPointGrid)
        if compiled is None:
            assert grid.fused == ((walls == "axis" or cell == "interval") and "rigid" not in kind)
            assert comm.allreduce(grid.contacts) > 0  # the bodies pressed into each other
        out.append((state(solver), np.array(dts)))
    (ref, dt_ref), (got, dt_got) = out
    assert np.allclose(dt_got, dt_ref, rtol=1e-12, atol=0.0)
    for a, b in zip(ref, got):
        scale = max(float(np.abs(a).max()), 1.0)
        assert np.abs(np.asarray(a) - np.asarray(b)).max() <= 1e-11 * scale


@pytest.mark.parametrize(("cell", "scheme", "kind"), [
    pytest.param(cell, scheme, kind, marks=() if 4 * j + k == 3 * i % 8 and i % 2 == 1 else pytest.mark.slow)
    for i, cell in enumerate(MESHES) for j, scheme in enumerate(["USL", "MUSL"])
    for k, kind in enumerate(["slip", "friction", "rigid, friction and gap", "friction, gap and walls by position"])])
def test_compiled_contact_with_consistent_mass_equals_the_numpy_contact_step(cell, scheme, kind):
    """A consistent matrix per deformable body (rows lumped at the contact nodes with friction),
    its velocity and acceleration solves, the smallest stable-step factor of the bodies. A given
    step: the stable one carries the bodies' Lanczos estimates of lambda_min(M_L^-1 M^g), whose
    sums run in another order in the compiled step (without friction's lumped contact rows they
    differed by up to 3e-8 relative on tetrahedra)."""
    mu = 0.0 if kind == "slip" else 0.4
    contact = Contact(field="group", friction=mu, gap=0.04 if "gap" in kind else None,
                      rigid=(1,) if "rigid" in kind else ())
    walls = "position" if "position" in kind else "axis"
    opts = StepOptions(scheme=scheme, flip=0.95, damping=0.3, mass="consistent")
    first = [make_solver(cell, opts, contact, walls, compiled).step() for compiled in (False, None)]
    assert abs(first[1] - first[0]) <= 1e-6 * first[0]  # the stable step: the smallest factor of the bodies
    out = []
    for compiled in (False, None):
        solver = make_solver(cell, opts, contact, walls, compiled)
        for _ in range(12):
            solver.step(0.2 * first[0])
        grid = solver.grid
        assert isinstance(grid, ContactGrid if compiled is False else ContactPointGrid)
        if compiled is None:
            assert grid.fused == ((walls == "axis" or cell == "interval") and "rigid" not in kind)
            assert len(grid.group_masses) == (1 if "rigid" in kind else 2)
            assert comm.allreduce(grid.contacts) > 0  # the bodies pressed into each other
        out.append(state(solver))
    for a, b in zip(*out):  # (the solves stop at their KSP's tolerance: on 2 ranks 1.05e-11 apart once)
        scale = max(float(np.abs(a).max()), 1.0)
        assert np.abs(np.asarray(a) - np.asarray(b)).max() <= 1e-10 * scale


def test_contact_takes_the_compiled_passes_only_where_they_apply():
    """FMPM mass and particle domains keep the numpy contact step; compiled=True names what the
    compiled contact needs."""
    cell = "triangle"
    for contact, options, why in [(Contact(field="group"), StepOptions(mass="fmpm2"),
                                   "mass fmpm2 with contact: lumped or consistent"),
                                  (Contact(field="group"), StepOptions(domain="cpdi1"),
                                   "particle domain cpdi1: point particles")]:
        solver = make_solver(cell, options, contact, "axis")
        assert type(solver.grid) is ContactGrid
        solver.compiled = True
        with pytest.raises(ValueError, match=r"no compiled grid takes these options: ContactPointGrid \(contact with "
                                             r"point particles, lumped or consistent mass.*\): " + why):
            _ = solver.grid
    assert type(make_solver(cell, StepOptions(), Contact(field="group"), "axis").grid) is ContactPointGrid
