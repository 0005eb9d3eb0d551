"""Multi-velocity-field contact in the loop (fempm.stepping.contact): one group is the single-field step,
bodies bounce apart instead of sticking, momentum is conserved to round-off, serial = 2 ranks."""

import dolfinx
import fempm
import numpy as np
import pytest
from mpi4py import MPI

from fempm.stepping.contact import Contact, shared_cells
from fempm.particles.corners import box_corners
from fempm.materials import LinearElastic
from fempm.scenes.disks import two_disks
from fempm.scene import run
from fempm.stepping import ExplicitSolver, StepOptions


comm = MPI.COMM_WORLD


def _gather_sorted(p, a):
    ids = np.concatenate(comm.allgather(p.ids))
    return np.concatenate(comm.allgather(a))[np.argsort(ids)]


@pytest.mark.parametrize("scheme", ["USL", "MUSL"])
@pytest.mark.parallel
def test_one_group_is_the_single_field_step(scheme):
    out = []
    for contact in (None, Contact(field="group", mass_cutoff=0.0)):  # the single field's cut-off
        scene = two_disks(cells=10, frames=0, scheme=scheme)
        scene.particles.fields["group"] = np.zeros(len(scene.particles), np.int32)
        solver = scene.solver()
        solver.compiled = False
        solver.contact = contact
        for _ in range(60):
            solver.step()
        out.append(_gather_sorted(scene.particles, scene.particles.x))
    np.testing.assert_allclose(out[1], out[0], rtol=0, atol=1e-14)


def _bars(contact, mass="lumped"):
    """Two elastic bars (E = rho = 1) on [0.1, 0.45] and [0.55, 0.9] moving at +-0.1."""
    mesh = dolfinx.mesh.create_interval(comm, 40, [0.0, 1.0])
    p = fempm.create_particles(mesh, 2, density=1.0,
                               cells=lambda x: ((x[0] > 0.1) & (x[0] < 0.45)) | ((x[0] > 0.55) & (x[0] < 0.9)))
    p.fields["group"] = (p.x[:, 0] > 0.5).astype(np.int32)
    p.fields["v"] = np.where(p.x[:, :1] < 0.5, 0.1, -0.1)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (1,)))
    return ExplicitSolver(V, p, [LinearElastic(1.0)], options=StepOptions(scheme="USL", mass=mass), contact=contact)


@pytest.mark.parametrize("mass", ["lumped", "consistent", "fmpm3"])
def test_two_bars_bounce_apart_with_contact(mass):
    """The bars meet at t = 0.5, stay in contact for the time a wave crosses a bar and back
    (0.7), and leave at about their initial speeds; momentum stays zero to round-off, also with
    each bar's own consistent mass (or FMPM) solved for its velocity and acceleration."""
    solver = _bars(Contact(field="group"), mass)
    p = solver.particles
    drift = 0.0
    while solver.t < 1.6:
        solver.step()
        drift = max(drift, abs(solver.energies()["momentum_x"]))
    g = p.fields["group"]
    v = [comm.allreduce(float(p.fields["v"][g == k].sum())) / comm.allreduce(int((g == k).sum())) for k in (0, 1)]
    assert v[0] < -0.09 and v[1] > 0.09  # apart at 90 % of the speed or more
    assert drift < (1e-15 if mass == "lumped" else 1e-13)
    gap = comm.allreduce(float(p.x[g == 1].min(initial=np.inf)), op=MPI.MIN) - \
        comm.allreduce(float(p.x[g == 0].max(initial=-np.inf)), op=MPI.MAX)
    assert gap > 2 * 1.0 / 40  # no cell holds both bars


def _disks_with_contact(c, mass="lumped"):
    scene = two_disks(cells=20, t_end=3.0, frames=0, scheme="USL", mass=mass, comm=c)
    p = scene.particles
    p.fields["group"] = (p.x[:, 0] > 0.5).astype(np.int32)
    scene.contact = Contact(field="group")
    solver = scene.solver()
    drift = 0.0
    while solver.t < 3.0 - 1e-12:
        solver.step(dt_max=3.0 - solver.t)
        e = solver.energies()
        drift = max(drift, abs(e["momentum_x"]), abs(e["momentum_y"]))
    ids = np.concatenate(c.allgather(p.ids))
    order = np.argsort(ids)
    return [np.concatenate(c.allgather(a))[order] for a in (p.x, p.fields["v"], p.fields["group"])] + [drift]


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
@pytest.mark.parallel(only=("lumped",))
def test_two_disks_separate_with_contact_and_serial_equals_two_ranks(mass):
    """The elastic disks with one field per disk (USL, CFL 0.4): after the impact they move
    apart, more than a cell from each other, with zero total momentum to round-off; the run on
    several ranks is the serial one. With consistent mass likewise."""
    x, v, g, drift = _disks_with_contact(comm, mass)
    assert drift < (1e-13 if mass == "lumped" else 1e-12)  # |momentum| of a disk 12.6; solves to rtol 1e-13
    assert v[g == 0].mean(axis=0) @ [1, 1] < -0.15 and v[g == 1].mean(axis=0) @ [1, 1] > 0.15  # moving apart
    gap = min(np.linalg.norm(x[g == 0] - y, axis=1).min() for y in x[g == 1])
    assert gap > 2 * 0.05
    if comm.size > 1:
        x1 = _disks_with_contact(MPI.COMM_SELF, mass)[0]
        np.testing.assert_allclose(x, x1, rtol=0, atol=1e-10)


@pytest.mark.parametrize("domain", ["cpdi2", "gimp"])
def test_disks_with_particle_domains_separate(domain):
    """CPDI2 corners move with their own disk's field (the disks would share the corners' grid
    velocity otherwise), GIMP domains likewise average each disk's own field: the disks rebound
    and separate with zero momentum."""
    scene = two_disks(cells=20, frames=0, scheme="USL", contact=True, comm=comm)
    scene.options = StepOptions(scheme="USL", domain=domain)
    p = scene.particles
    if domain == "cpdi2":  # square domains that tile the disks (their particles' volumes)
        p.fields["corners"] = box_corners(p.x, np.repeat(0.5 * np.sqrt(p.volume)[:, None], 2, axis=1))
    summary = run(scene, progress=False)
    g = p.fields["disk"]
    v = [comm.allreduce(p.mass[g == k] @ p.fields["v"][g == k]) for k in (0, 1)]
    assert v[0] @ [1, 1] < -0.15 * 125 and v[1] @ [1, 1] > 0.15 * 125  # apart (each disk ~126 kg)
    assert summary["health"]["momentum_drift"] < 1e-13
    assert shared_cells(p, "disk") == 0


@pytest.mark.parallel
def test_shared_cells_counts_the_cells_holding_two_groups():
    """Apart, the disks share no cell; the particle of the lower disk nearest (0.21, 0.23),
    relabelled as the upper disk, shares exactly its own (full) cell with it."""
    p = two_disks(cells=10, frames=0, comm=comm).particles
    assert shared_cells(p, "disk") == 0
    r = np.linalg.norm(p.x - [0.21, 0.23], axis=1)  # one nearest particle, inside a full cell
    nearest = comm.allreduce(float(r.min(initial=np.inf)), op=MPI.MIN)
    p.fields["disk"][r == nearest] = 1
    assert shared_cells(p, "disk") == 1


@pytest.mark.parallel
def test_contact_refuses_what_it_does_not_support():
    scene = two_disks(cells=6, frames=0, scheme="USL")
    solver = scene.solver()
    solver.contact = Contact(field="nothing")
    with pytest.raises(ValueError, match="no field 'nothing'"):
        solver.step()
    scene.particles.fields["group"] = np.full(len(scene.particles), -1)
    solver.contact = Contact(field="group")
    with pytest.raises(ValueError, match="non-negative integer group"):
        solver.step()
    solver.options = StepOptions(scheme="USF")
    with pytest.raises(ValueError, match="USL and MUSL"):
        solver.step()
    solver.options = StepOptions(mass="fmpm2")
    solver.compiled = True
    with pytest.raises(ValueError, match="no compiled grid takes these options: ContactPointGrid .*: mass fmpm2 with contact: "
                                         "lumped or consistent"):
        solver.step()
