"""The incline scene (fempm.scenes.incline): a block slides with g (sin(theta) - mu cos(theta))
within 2 % at two resolutions and sticks where mu > tan(theta), on the grid plane, on a
rigid plane and on the tagged floor of a turned gmsh mesh; a disk rolls with 2/3 g sin(theta) or slides; serial = 2 ranks; the CLI writes
both figures. (docs/incline.md has the study at 8 and 16 cells.)"""

import json

import numpy as np
import pytest
from mpi4py import MPI

from fempm.scene import run
from fempm.scenes.incline import analytic_acceleration, incline


comm = MPI.COMM_WORLD


@pytest.mark.parametrize("mu", [0.0, 0.2])
def test_a_block_slides_with_the_analytic_acceleration(mu):
    g_sin = 9.81 * np.sin(np.radians(30.0))
    for cells in (4, 8):
        summary = run(incline("block", 30.0, mu, cells=cells, frames=0), progress=False)
        assert summary["analytic"] == pytest.approx(g_sin - mu * 9.81 * np.cos(np.radians(30.0)), rel=1e-14)
        assert summary["acceleration"] == pytest.approx(summary["analytic"], rel=0.02), cells


def test_a_block_sticks_above_the_friction_angle():
    summary = run(incline("block", 30.0, 1.0, cells=4, frames=0), progress=False)
    assert summary["analytic"] == 0.0
    assert abs(summary["acceleration"]) < 0.02 * 9.81 * np.sin(np.radians(30.0))


G_SIN = 9.81 * np.sin(np.radians(30.0))


@pytest.mark.parametrize("plane", ["grid", "rigid"])
@pytest.mark.parametrize("mu", [0.5, 0.6])
def test_a_block_near_the_friction_angle_slides_or_sticks_with_the_scene_defaults(mu, plane):
    """mu = 0.5 (13 % below tan(30 deg) = 0.577) slides with g (sin - mu cos) within 2 %,
    mu = 0.6 (4 % above it) sticks, with the scene's default PIC/FLIP blend of the block (0.7):
    with pure FLIP the frictional sliding of the elastic block is unstable (1.25 m/s^2 against
    0.657 at 8 cells, 3.06 at 16; it slides at mu = 0.6). Measured at 8 cells: -0.03 % and
    0.028 m/s^2 (grid), +0.00 % and 0.031 (rigid)."""
    summary = run(incline("block", 30.0, mu, cells=8, plane=plane, frames=0), progress=False)
    assert summary["params"]["flip"] == 0.7
    if mu < np.tan(np.radians(30.0)):
        assert summary["acceleration"] == pytest.approx(summary["analytic"], rel=0.02)
    else:
        assert summary["analytic"] == 0.0 and abs(summary["acceleration"]) < 0.01 * G_SIN


@pytest.mark.skipif(comm.size > 1, reason="the accuracy in serial")
@pytest.mark.parametrize(("mu", "plane"), [(0.5, "grid"), pytest.param(0.6, "grid", marks=pytest.mark.slow),
                                           pytest.param(0.5, "rigid", marks=pytest.mark.slow),
                                           pytest.param(0.6, "rigid", marks=pytest.mark.slow)])
def test_a_block_on_a_frictional_plane_with_consistent_mass(mu, plane):
    """Consistent mass, PIC (damps the sliding instability, as consistent mass does not): the
    rows of the frictional wall's and contact's nodes are lumped, so that node-wise Coulomb
    friction acts on velocities that do not oscillate from node to node. Before, the wall took
    0.47 instead of 0.5 of its normal impulse as friction: +23 % at mu = 0.5 (+19 % on the rigid
    plane) and sliding at mu = 0.6. Measured at 4 cells: -0.00 % / +0.01 %, at rest."""
    import dataclasses

    scene = incline("block", 30.0, mu, cells=4, plane=plane, flip=0.0, frames=0)
    scene.options = dataclasses.replace(scene.options, mass="consistent")
    summary = run(scene, progress=False)
    if mu < np.tan(np.radians(30.0)):
        assert summary["acceleration"] == pytest.approx(summary["analytic"], rel=0.02)
    else:
        assert abs(summary["acceleration"]) < 0.01 * G_SIN


@pytest.mark.parametrize("mu", [pytest.param(0.0, marks=pytest.mark.slow), 0.2, 0.5, 0.6,
                                pytest.param(0.7, marks=pytest.mark.slow)])
@pytest.mark.parallel(only=("0.2",))
def test_a_block_on_a_tagged_inclined_wall(mu):
    """The slope as the tagged floor of a gmsh triangle mesh turned by 30 degrees (gravity
    vertical, fempm.boundary.tagged): slides with g (sin - mu cos) within 2 % below the friction
    angle (measured at 8 cells: +0.001 %, 0.000 %; at 4 cells, mu = 0.5: -0.005 %), sticks above
    it (mu = 0.6, 4 % above tan(30 deg), and 0.7); 1 and 2 ranks alike (docs/incline.md has 16
    cells)."""
    cells = 8 if mu in (0.0, 0.2) else 4
    summary = run(incline("block", 30.0, mu, cells=cells, plane="tagged", frames=0), progress=False)
    if mu < np.tan(np.radians(30.0)):
        assert summary["acceleration"] == pytest.approx(summary["analytic"], rel=0.02)
    else:
        assert summary["analytic"] == 0.0 and abs(summary["acceleration"]) < 0.01 * G_SIN
    with pytest.raises(ValueError, match=r"plane='tagged' takes the block with gap=0"):
        incline("disk", plane="tagged")


def test_a_block_slides_on_a_rigid_plane():
    summary = run(incline("block", 30.0, 0.2, cells=4, plane="rigid", frames=0), progress=False)
    assert summary["acceleration"] == pytest.approx(summary["analytic"], rel=0.02)  # measured +0.45 %


@pytest.mark.skipif(comm.size > 1, reason="the accuracy in serial; test_the_disk_on_several_ranks checks the partition")
@pytest.mark.parametrize("mu, plane", [(0.3, "grid"), (0.2, "grid"), (0.1, "grid"), (0.2, "rigid")])
def test_a_disk_rolls_or_slides_with_the_analytic_acceleration(mu, plane):
    """4 cells across the radius, 4 x 4 particles per cell: at mu = 0.3 and at 0.2, 4 % above
    the threshold tan(30)/3 = 0.192, it rolls (measured -0.14 % and +1.54 %: the wall shares
    its normal impulse over the nodes the disk touches; node by node it slid at 0.2), at 0.1 it
    slides (-0.03 %). On the rigid plane, which shares its normal impulse over the approaching
    nodes, mu = 0.2 gave -0.56 % (node by node it slid); mu = 0.3 and 0.1 gave -1.48 % and
    +0.13 % (add them here, 10 s each); docs/incline has 8 and 16 cells."""
    summary = run(incline("disk", 30.0, mu, cells=4, plane=plane, frames=0), progress=False)
    rolling = 2.0 / 3.0 * G_SIN
    rolls = mu >= np.tan(np.radians(30.0)) / 3.0
    assert summary["analytic"] == pytest.approx(rolling if rolls else G_SIN - mu * 9.81 * np.cos(np.radians(30.0)))
    assert summary["acceleration"] == pytest.approx(summary["analytic"], rel=0.02)


def _disk_steps(c, plane):
    scene = incline("disk", 30.0, 0.3, cells=4, plane=plane, frames=0, comm=c)
    solver = scene.solver()
    for _ in range(60):
        solver.step()
    p = scene.particles
    ids = np.concatenate(c.allgather(p.ids))
    return np.concatenate(c.allgather(p.x))[np.argsort(ids)]


@pytest.mark.skipif(comm.size == 1, reason="compares several ranks with one")
@pytest.mark.parametrize("plane", ["grid", "rigid"])
@pytest.mark.parallel
def test_the_disk_on_several_ranks(plane):
    """The wall's and the contact's position checks (nodal centres of mass summed over ranks)
    give the serial run to 1e-10."""
    np.testing.assert_allclose(_disk_steps(comm, plane), _disk_steps(MPI.COMM_SELF, plane), rtol=0, atol=1e-10)


def test_analytic_accelerations():
    g = 9.81
    th = np.radians(30.0)
    assert analytic_acceleration("block", 30.0, 0.7) == 0.0
    assert analytic_acceleration("disk", 30.0, 0.2) == pytest.approx(2 / 3 * g * np.sin(th), rel=1e-14)  # rolls
    assert analytic_acceleration("disk", 30.0, 0.1) == pytest.approx(g * (np.sin(th) - 0.1 * np.cos(th)), rel=1e-14)


@pytest.mark.parallel
def test_cli_writes_acceleration_and_analytic(tmp_path):
    from fempm.cli import main

    out = MPI.COMM_WORLD.bcast(str(tmp_path), root=0)
    assert main(["run", "incline", "--body", "block", "--angle", "20", "--friction", "0.1", "--cells", "4",
                 "--out", out + "/run"]) == 0
    summary = json.load(open(out + "/run/summary.json"))
    assert summary["acceleration"] == pytest.approx(summary["analytic"], rel=0.02)
    with pytest.raises(ValueError, match="unknown option body"):
        incline(body="sphere")
