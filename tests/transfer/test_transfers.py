"""The velocity transfers (fempm.transfer.transfers): APIC and TPIC map an affine velocity field
exactly for every mass model, cell type, degree and particle domain; XPIC(1) is PIC and XPIC(m)
with the lumped mass is FMPM(m) with lumped forces and PIC; the spinning disk keeps its angular
momentum with APIC, and on fine grids with ``affine_cutoff``; bad options are clear errors."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import basix.ufl
import dolfinx.fem
import numpy as np
import pytest
from conftest import make_mesh
from mpi4py import MPI

import fempm
from fempm import StepOptions
from fempm.materials import LinearElastic
from fempm.particles.seeding import create_particles
from fempm.scenes import spin
from fempm.stepping.contact import Contact
from fempm.stepping.options import SimulationError
from fempm.transfer.affine import affine_velocity
from fempm.transfer.transfers import AFFINE_FIELD, SPIN_FIELD, velocity_transfer

CELLS = ("triangle", "quadrilateral", "tetrahedron", "hexahedron")
#: the compiled cases of the default run (each compiles its kernels' variants: the others are slow)
COMPILED_DEFAULT = {("triangle", "apic", "lumped"), ("triangle", "apic", "consistent")}


def _affine_step(mesh_name: str, transfer: str, mass: str, *, degree: int = 1, variant: str | None = None,
                 domain: str = "point", compiled: bool | None = False, scheme: str = "USL",
                 integrator: str = "explicit"):
    """One step of a stress-free body whose particles carry v = a + C x (and C): the largest
    error of the particles' velocities against the field at their old positions, and of their
    affine matrices against C."""
    mesh = make_mesh(mesh_name)
    d = mesh.geometry.dim
    if variant:
        element = basix.ufl.element("Lagrange", mesh.basix_cell(), degree, getattr(basix.LagrangeVariant, variant),
                                    shape=(d,))
        V = dolfinx.fem.functionspace(mesh, element)
    else:
        V = dolfinx.fem.functionspace(mesh, ("Lagrange", degree, (d,)))
    inside = None if domain == "point" else (lambda x: np.all((x[:d] > 0.2) & (x[:d] < 0.8), axis=0))  # domains in the mesh
    p = create_particles(mesh, 9 if d == 2 else 8, density=1.0, where=inside, corners=domain == "cpdi2")
    rng = np.random.default_rng(3)
    a, C = rng.normal(size=d), rng.normal(size=(d, d))
    p.fields["v"] = a + p.x @ C.T
    opts = StepOptions(transfer=transfer, mass=mass, scheme=scheme, domain=domain, lump_below=0.0, mass_cutoff=0.0,
                       integrator=integrator)
    solver = fempm.Solver(V, p, [LinearElastic(1.0, 0.3)], options=opts, compiled=compiled)
    solver.set_velocity_gradient(C)
    x0 = p.x.copy()
    solver.step(1e-7)
    err_v = p.comm.allreduce(float(np.abs(p.fields["v"] - (a + x0 @ C.T)).max(initial=0.0)), op=MPI.MAX)
    A = p.fields.get(AFFINE_FIELD, C)
    err_C = p.comm.allreduce(float(np.abs(A - C).max(initial=0.0)), op=MPI.MAX)
    return err_v, err_C


def _cases():
    for cell in CELLS:
        for transfer in ("apic", "tpic"):
            for mass in ("lumped", "consistent", "fmpm2"):
                yield pytest.param(cell, transfer, mass, False, id=f"{cell}-{transfer}-{mass}-numpy",
                                   marks=[pytest.mark.parallel] if cell == "triangle" else [])
                slow = (cell, transfer, mass) not in COMPILED_DEFAULT
                yield pytest.param(cell, transfer, mass, None, id=f"{cell}-{transfer}-{mass}-compiled",
                                   marks=[pytest.mark.slow] if slow else [pytest.mark.parallel])


@pytest.mark.parametrize(("cell", "transfer", "mass", "compiled"), list(_cases()))
def test_an_affine_field_survives_p2g_then_g2p(cell, transfer, mass, compiled):
    err_v, err_C = _affine_step(cell, transfer, mass, compiled=compiled)
    assert err_v < 1e-11 and err_C < 1e-10, (err_v, err_C)


@pytest.mark.parametrize("case", [
    ("triangle", "apic", "lumped", 2, "bernstein", "point"),
    ("tetrahedron", "tpic", "lumped", 2, "bernstein", "point"),
    ("triangle", "apic", "consistent", 2, None, "point"),
    ("distorted-quadrilateral", "apic", "lumped", 1, None, "point"),
    ("quadrilateral", "apic", "lumped", 1, None, "gimp"),
    ("triangle", "tpic", "fmpm2", 1, None, "cpdi1"),
    ("quadrilateral", "apic", "consistent", 1, None, "cpdi2"),
])
def test_an_affine_field_survives_on_degree_2_distorted_cells_and_particle_domains(case):
    cell, transfer, mass, degree, variant, domain = case
    err_v, err_C = _affine_step(cell, transfer, mass, degree=degree, variant=variant, domain=domain)
    assert err_v < 1e-11 and err_C < 1e-9, (err_v, err_C)


@pytest.mark.slow
@pytest.mark.parametrize("case", [
    ("triangle", "apic", "lumped", 2, "bernstein", "point"),
    ("tetrahedron", "tpic", "lumped", 2, "bernstein", "point"),
    ("triangle", "apic", "consistent", 2, None, "point"),
    ("distorted-quadrilateral", "apic", "lumped", 1, None, "point"),
    ("interval", "apic", "lumped", 1, None, "point"),
])
def test_the_compiled_generic_passes_map_an_affine_field(case):
    """The generic kernels (degree 2, multilinear cells, intervals) as the numpy step."""
    cell, transfer, mass, degree, variant, domain = case
    err_v, err_C = _affine_step(cell, transfer, mass, degree=degree, variant=variant, domain=domain, compiled=None)
    assert err_v < 1e-11 and err_C < 1e-9, (err_v, err_C)


@pytest.mark.parallel
@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_the_implicit_step_maps_an_affine_field_with_apic(mass):
    err_v, err_C = _affine_step("triangle", "apic", mass, integrator="implicit")
    assert err_v < 1e-9 and err_C < 1e-8, (err_v, err_C)


@pytest.mark.slow
def test_xpic_1_and_2_map_like_the_numpy_step_in_1d_and_on_domains():
    """The compiled XPIC passes (interval: the generic kernels; CPDI1: the domain grid) against
    the numpy step."""
    for mesh_name, domain in (("interval", "point"), ("quadrilateral", "cpdi1")):
        runs = [_xpic_steps(mesh_name, domain, compiled) for compiled in (False, None)]
        assert np.allclose(*runs, rtol=0, atol=1e-12)


def _xpic_steps(mesh_name: str, domain: str, compiled):
    mesh = make_mesh(mesh_name)
    d = mesh.geometry.dim
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (d,)))
    p = create_particles(mesh, 2 ** d, density=1.0, where=lambda x: np.all((x[:d] > 0.2) & (x[:d] < 0.8), axis=0))
    p.fields["v"] = np.sin(3.0 * p.x)
    opts = StepOptions(transfer="xpic", xpic_order=2, scheme="MUSL", domain=domain)
    solver = fempm.Solver(V, p, [LinearElastic(10.0, 0.3)], options=opts, compiled=compiled)
    for _ in range(3):
        solver.step(1e-3)
    return p.comm.allgather(p.fields["v"][np.argsort(p.ids)])[0]


def test_pic_and_flip_lose_the_affine_part_that_apic_keeps():
    """The same step with PIC (lumped) misses the field by far: the test above can fail."""
    err_v, _ = _affine_step("triangle", "pic", "lumped")
    assert err_v > 1e-2


def _spin(transfer: str, mass: str = "lumped", steps: int = 40, compiled: bool | None = False, **changes):
    """``steps`` steps of the spinning disk (the numpy step by default: the compiled passes are
    tested against it above)."""
    scene = spin(cells=10, t_end=1.0, frames=0)
    scene.options = dataclasses.replace(scene.options, transfer=transfer, mass=mass, **changes)
    solver = scene.solver()
    solver.compiled = compiled
    p = solver.particles
    e0, L0 = solver.energies(), solver.angular_momentum()["angular_momentum"]
    for _ in range(steps):
        solver.step()
    e = solver.energies()
    return solver, e["kinetic"] / e0["kinetic"], abs(solver.angular_momentum()["angular_momentum"] / L0 - 1), p


@pytest.mark.parametrize("scheme", ["USL", "MUSL"])
@pytest.mark.parallel
def test_xpic_1_is_pic_and_xpic_m_is_fmpm_m_with_lumped_forces_and_pic(scheme):
    """XPIC(1) is PIC step after step; XPIC(m)'s particle velocities after a step are those of
    FMPM(m) with lumped forces and PIC (the strain rate and, with MUSL, the motion then differ:
    XPIC takes them from the lumped grid velocity, FMPM from its series)."""
    _, _, _, pic = _spin("pic", steps=15, scheme=scheme, compiled=None)
    _, _, _, xpic1 = _spin("xpic", xpic_order=1, steps=15, scheme=scheme, compiled=None)
    assert np.allclose(xpic1.fields["v"], pic.fields["v"], rtol=0, atol=1e-13)
    _, _, _, xpic3 = _spin("xpic", xpic_order=3, steps=1, scheme=scheme, compiled=None)
    _, _, _, fmpm3 = _spin("pic", mass="fmpm3", lumped_forces=True, steps=1, scheme=scheme, compiled=None)
    assert np.allclose(xpic3.fields["v"], fmpm3.fields["v"], rtol=0, atol=1e-12)
    _, _, _, pic1 = _spin("pic", steps=1, scheme=scheme, compiled=None)
    assert np.abs(xpic3.fields["v"] - pic1.fields["v"]).max() > 1e-3  # (and it is not PIC)


@pytest.mark.parallel
def test_apic_keeps_the_spinning_disks_angular_momentum_and_pic_loses_its_energy():
    solver, kinetic, drift, p = _spin("apic", steps=60)
    assert drift < 1e-10 and kinetic > 0.99, (drift, kinetic)
    assert p.fields[SPIN_FIELD].shape == (len(p), 1)
    _, kinetic_pic, _, _ = _spin("pic", steps=60)
    assert kinetic_pic < 0.5
    _, kinetic_tpic, drift_tpic, _ = _spin("tpic", steps=60)
    assert kinetic_tpic > 0.99 and drift_tpic > 1e-6  # TPIC transports C: its spin leaks as D changes


@pytest.mark.parallel
def test_apic_with_the_consistent_mass_keeps_the_angular_momentum():
    """The exact projection leaves the affine part out and keeps the angular momentum by itself
    (no lumped row: lump_below=0, the scene's)."""
    _, kinetic, drift, _ = _spin("apic", mass="consistent", steps=40)
    assert drift < 1e-10 and kinetic > 0.99, (drift, kinetic)


def test_the_affine_cutoff_weights_weak_nodes_accelerations_by_their_mass():
    rng = np.random.default_rng(5)
    v_old, v_new = rng.normal(size=(4, 2)), rng.normal(size=(4, 2))
    mass = np.array([2.0, 1.0, 0.5, 0.0])
    assert affine_velocity(v_new, v_old, mass, 0.0) is v_new
    v = affine_velocity(v_new, v_old, mass, 1.0)
    expected = v_old + np.array([1.0, 1.0, 0.5, 1.0])[:, None] * (v_new - v_old)  # (no particle reads a massless node)
    assert np.allclose(v, expected, rtol=0, atol=1e-15)
    assert affine_velocity(v_new, v_old, mass, 0.5) is v_new  # no node with mass below the cutoff


def test_the_compiled_cutoff_velocity_is_the_numpy_one():
    """fempm.kernels.grid_update.affine_cutoff_velocity: the numpy reference's velocity and
    a flag on its weak nodes (a massless node none of them)."""
    from fempm.kernels.grid_update import affine_cutoff_velocity
    from fempm.transfer.affine import weak_nodes

    rng = np.random.default_rng(6)
    v_old, v_new = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    mass = rng.uniform(0.0, 1.0, 50)
    mass[::7] = 0.0
    v, flags = np.full_like(v_new, np.nan), np.full(50, 7, dtype=np.uint8)
    count = affine_cutoff_velocity(v_new, v_old, mass, 0.3, v, flags)
    nodes = weak_nodes(mass, 0.3)
    assert count == len(nodes) > 0 and np.array_equal(np.flatnonzero(flags), nodes)
    assert np.allclose(v, affine_velocity(v_new, v_old, mass, 0.3), rtol=0, atol=1e-15)


@pytest.mark.parametrize("mesh", ["triangle", "quadrilateral"])
def test_the_compiled_affine_cutoff_is_the_numpy_one(mesh):
    """APIC with ``affine_cutoff`` in the scalar 2D passes as in the numpy step (the state after
    20 steps of the spinning disk, whose rim nodes fall under the cutoff)."""
    states = []
    for compiled in (False, None):
        scene = spin(cells=10, mesh=mesh, t_end=1.0, frames=0)
        scene.options = dataclasses.replace(scene.options, transfer="apic", affine_cutoff=0.05)
        solver = scene.solver()
        solver.compiled = compiled
        for _ in range(20):
            solver.step()
        states.append(_sorted_state(solver))
    assert np.abs(states[0] - states[1]).max() < 1e-11
    scene = spin(cells=10, mesh=mesh, t_end=1.0, frames=0)
    scene.options = dataclasses.replace(scene.options, transfer="apic", affine_cutoff=0.0)
    solver = scene.solver()
    for _ in range(20):
        solver.step()
    assert np.abs(_sorted_state(solver) - states[1]).max() > 1e-6  # (the cutoff changes the state)


@pytest.mark.slow
@pytest.mark.parametrize("cell", ["tetrahedron", "hexahedron", "distorted-quadrilateral"])
def test_the_3d_and_generic_passes_affine_cutoff_is_the_numpy_one(cell):
    """The scalar 3D passes (:mod:`fempm.kernels.solid`) and the generic ones (multilinear cells)
    with APIC, MUSL and ``affine_cutoff`` as the numpy step: two steps of a strained body, a
    cutoff that weighs most nodes."""
    states = []
    for compiled in (False, None):
        mesh = make_mesh(cell)
        d = mesh.geometry.dim
        V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (d,)))
        p = create_particles(mesh, 8 if d == 3 else 9, density=1.0,
                             where=lambda x, d=d: np.all((x[:d] > 0.2) & (x[:d] < 0.7), axis=0))
        p.fields["v"] = np.random.default_rng(2).normal(size=(len(p), d))
        opts = StepOptions(transfer="apic", affine_cutoff=0.5, mass_cutoff=0.0)
        solver = fempm.Solver(V, p, [LinearElastic(1.0, 0.3)], options=opts, compiled=compiled)
        solver.step(1e-3)  # (a first step to strain the body)
        p.fields["F"][:] = np.eye(d) + 0.01 * np.arange(d * d).reshape(d, d) / d
        p.fields["sigma"][:] = np.arange(d * d).reshape(d, d) / d
        solver.step(1e-3)
        f = p.fields
        states.append(np.hstack([f["v"], f[AFFINE_FIELD].reshape(len(p), -1), f[SPIN_FIELD]]))
    assert np.abs(states[0] - states[1]).max() < 1e-11


def test_the_affine_cutoff_holds_apic_and_tpic_on_a_fine_grid():
    """At 30 cells across the disk's rim nodes feed their accelerations back through the
    affine matrices: APIC and TPIC at the CFL step grow energy and stop; with
    ``affine_cutoff=0.01`` (the default) they run on, APIC's angular momentum kept to
    round-off (its spin is that of the updated grid velocity) and the kinetic energy within
    1 %."""
    def run(transfer, cut, steps=200):
        scene = spin(cells=30, t_end=1.0, frames=0)
        scene.options = dataclasses.replace(scene.options, transfer=transfer, affine_cutoff=cut)
        solver = scene.solver()
        e0, L0 = solver.energies()["kinetic"], solver.angular_momentum()["angular_momentum"]
        for _ in range(steps):
            solver.step()
        return solver.energies()["kinetic"] / e0, abs(solver.angular_momentum()["angular_momentum"] / L0 - 1)

    with pytest.raises(SimulationError):
        run("apic", 0.0)
    kinetic, drift = run("apic", 0.01)
    assert kinetic > 0.99 and drift < 1e-11, (kinetic, drift)
    kinetic, drift = run("tpic", 0.01)
    assert kinetic > 0.99 and drift < 1e-2, (kinetic, drift)


def test_angular_momentum_columns_in_2d_and_3d():
    solver, *_ = _spin("apic", steps=1)
    row = solver.energies()
    assert "angular_momentum" in row
    mesh = make_mesh("tetrahedron")
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    p = create_particles(mesh, 8, density=2.0)
    omega = np.array([0.3, -0.2, 0.5])
    p.fields["v"] = np.cross(omega, p.x)
    solver = fempm.Solver(V, p, [LinearElastic(1.0, 0.3)])
    row = solver.energies()
    expected = p.comm.allreduce(p.mass @ np.cross(p.x, p.fields["v"]))
    assert np.allclose([row[f"angular_momentum_{c}"] for c in "xyz"], expected, rtol=1e-14)


def test_bad_transfer_options_are_clear_errors():
    with pytest.raises(ValueError, match="unknown option transfer='foo'"):
        StepOptions(transfer="foo")
    with pytest.raises(ValueError, match="xpic_order=0 must be an integer"):
        StepOptions(transfer="xpic", xpic_order=0)
    with pytest.raises(TypeError, match="xpic_order"):
        StepOptions(transfer="xpic", xpic_order=2.5)
    with pytest.raises(ValueError, match="implicit step takes transfer"):
        StepOptions(transfer="tpic", integrator="implicit")
    with pytest.raises(ValueError, match="affine_cutoff=0.01 applies to transfer='apic' or 'tpic', not 'flip'"):
        StepOptions(affine_cutoff=0.01)
    with pytest.raises(ValueError, match=r"affine_cutoff=1.5 must lie in \[0, 1\)"):
        StepOptions(transfer="apic", affine_cutoff=1.5)
    with pytest.raises(ValueError, match="implicit step takes no affine_cutoff"):
        StepOptions(transfer="apic", affine_cutoff=0.01, integrator="implicit")
    assert velocity_transfer("pic").blend == 0.0 and velocity_transfer("flip", flip=0.7).blend == 0.7
    mesh = make_mesh("quadrilateral")
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    p = create_particles(mesh, 4, density=1.0)
    p.fields["group"] = (p.x[:, 0] > 0.5).astype(np.int32)
    solver = fempm.Solver(V, p, [LinearElastic(1.0, 0.3)], options=StepOptions(transfer="apic"),
                          contact=Contact(field="group"))
    with pytest.raises(ValueError, match="contact .* takes transfer='flip' or 'pic', not 'apic'"):
        solver.step()
    solver = fempm.Solver(V, p, [LinearElastic(1.0, 0.3)], options=StepOptions(transfer="apic"))
    p.fields[AFFINE_FIELD] = np.zeros((len(p), 3, 3))
    with pytest.raises(ValueError, match="'affine' has shape"):
        solver.step()
    with pytest.raises(ValueError, match="velocity gradient has shape"):
        solver.set_velocity_gradient(np.eye(3))


def _spin_scene(t_end: float):
    scene = spin(cells=10, t_end=t_end, frames=2)
    scene.options = dataclasses.replace(scene.options, transfer="apic")
    return scene


def _sorted_state(solver) -> np.ndarray:
    """The particles' velocity, affine matrix and spin, by id, over all ranks."""
    p = solver.particles
    f = p.fields
    mine = np.hstack([p.ids[:, None], f["v"], f[AFFINE_FIELD].reshape(len(p), -1), f[SPIN_FIELD]])
    every = np.vstack(p.comm.allgather(mine))
    return every[np.argsort(every[:, 0])]


@pytest.mark.parallel
def test_the_affine_state_is_checkpointed_and_resumed(tmp_path):
    """A run interrupted half way and resumed from its checkpoint ends in the state of the run
    that was not (the affine fields written, migrated and read back with the others)."""
    import os
    import signal

    from fempm.io.checkpoint import RunInterrupted
    from fempm.scene import run

    comm = MPI.COMM_WORLD
    whole, parts = (Path(comm.bcast(str(tmp_path / name) if comm.rank == 0 else None)) for name in ("whole", "parts"))
    reference = run(_spin_scene(0.06), whole, progress=False)

    def interrupt(solver):
        if solver.t >= 0.03 and not interrupt.sent:
            interrupt.sent = True
            os.kill(os.getpid(), signal.SIGINT)
    interrupt.sent = False
    with pytest.raises(RunInterrupted):
        run(_spin_scene(0.06), parts, progress=False, checkpoint_every=1000, callback=interrupt)
    resumed = run(_spin_scene(0.06), parts, progress=False, resume=True)
    assert resumed["steps"] == reference["steps"]
    assert np.array_equal(_sorted_state(resumed["solver"]), _sorted_state(reference["solver"]))
    assert resumed["angular_momentum_drift"] == reference["angular_momentum_drift"] < 1e-10


@pytest.mark.parametrize("argv, message", [
    (["--transfer", "foo"], "option --transfer expects one of flip, pic, apic, tpic, xpic, got 'foo'"),
    (["--transfer", "xpic", "--xpic-order", "0"], "option --xpic-order expects a positive number of series terms"),
    (["--xpic-order", "3"], "option --xpic-order applies to --transfer xpic"),
    (["--transfer", "xpic", "--xpic-order", "11"], "xpic_order=11 must be an integer in [1, 10]"),
    (["--affine-cutoff", "0.01"], "option --affine-cutoff applies to --transfer apic or tpic"),
    (["--transfer", "apic", "--affine-cutoff", "x"], "option --affine-cutoff expects a number, got 'x'"),
    (["--transfer", "apic", "--affine-cutoff", "-1"], "affine_cutoff=-1.0 must lie in [0, 1)"),
])
def test_bad_transfer_options_on_the_command_line_exit_2_with_one_line(argv, message, capsys, tmp_path):
    from fempm.cli import main

    code = main(["run", "spin", "--cells", "4", "--t-end", "0.01", "--frames", "0", "--out", str(tmp_path), *argv])
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err


def test_a_transfer_from_the_command_line_writes_the_angular_momentum(tmp_path):
    from fempm.cli import main

    assert main(["run", "spin", "--cells", "6", "--t-end", "0.02", "--frames", "0", "--out", str(tmp_path),
                 "--transfer", "apic"]) == 0
    import csv
    import json

    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["angular_momentum_drift"] < 1e-10 and summary["kinetic_ratio"] > 0.99
    rows = list(csv.DictReader(open(tmp_path / "energies.csv")))
    assert float(rows[-1]["angular_momentum"]) == pytest.approx(float(rows[0]["angular_momentum"]), rel=1e-10)
