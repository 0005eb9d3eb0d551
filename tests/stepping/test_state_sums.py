"""The energies and momentum a step sums in its compiled particle passes (``step(totals=True)``,
:meth:`ExplicitSolver.step_energies`) against :meth:`ExplicitSolver.energies` computed from the
state, their numpy reference: equal to round-off after every scheme, on every cell type, with
the compiled laws and a law without a kernel, on 1 and 2 ranks; and ``fempm.run`` records the
same energies as it did from the state."""

import fempm  # noqa: F401  (before dolfinx)
import numpy as np
import pytest
from mpi4py import MPI

from fempm.materials.newtonian_eos import NewtonianTait
from fempm.stepping import StepOptions
from fempm.stepping.diagnostics import momentum_scale
from fempm.stepping.lumped import PointGrid

from tests.matrix import covering
from tests.stepping.test_compiled_step import MESHES, make_solver

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)


def assert_same_energies(solver):
    row, scale = solver.step_energies()
    ref = solver.energies()
    assert row.keys() == ref.keys()
    size = ref["kinetic"] + abs(ref["strain"])
    assert size > 0
    for k in ("kinetic", "strain", "total"):
        assert abs(row[k] - ref[k]) <= 1e-12 * size, (k, row[k], ref[k])
    p = solver.particles
    mass = p.comm.allreduce(float(p.mass.sum()))
    vmax = p.comm.allreduce(float(np.abs(p.fields["v"]).max(initial=0.0)), op=MPI.MAX)
    for k in ref:
        if k.startswith("momentum_"):  # the momenta may nearly cancel: to round-off of sum_p M_p |v_p|
            assert abs(row[k] - ref[k]) <= 1e-12 * mass * vmax, k
    assert scale == pytest.approx(momentum_scale(p), rel=1e-12)
    return row


@pytest.mark.parametrize(("cell", "scheme"), covering(list(MESHES), ["USL", "USF", "MUSL"]))
def test_sums_of_the_passes_equal_the_state(cell, scheme):
    solver = make_solver(cell, StepOptions(scheme=scheme, flip=0.9))
    assert isinstance(solver.grid, PointGrid)
    for _ in range(4):
        solver.step(totals=True)
        assert solver.grid.state_sums() is not None
        assert_same_energies(solver)


@pytest.mark.parametrize("cell", ["triangle", "hexahedron"])
def test_law_without_a_kernel_adds_its_energy_from_the_state(cell):
    solver = make_solver(cell, StepOptions(scheme="MUSL"), law=NewtonianTait(1.0, 30.0, 7.0, 0.0))
    for _ in range(3):
        solver.step(totals=True)
    row = assert_same_energies(solver)
    assert row["strain"] != 0.0


def test_without_totals_the_energies_come_from_the_state():
    solver = make_solver("triangle", StepOptions(scheme="USL"))
    solver.step(totals=True)
    solver.step()  # no sums: step_energies() computes them from the state, exactly as energies()
    assert solver.grid.state_sums() is None
    row, scale = solver.step_energies()
    assert row == solver.energies()
    assert scale == momentum_scale(solver.particles)


def test_the_generic_step_has_no_sums():
    solver = make_solver("quadrilateral", StepOptions(scheme="USL"), compiled=False)
    solver.step(totals=True)
    assert solver.grid.state_sums() is None
    row, _ = solver.step_energies()
    assert row == solver.energies()
