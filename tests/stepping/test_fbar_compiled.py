"""F-bar on the compiled point grid (fempm.stepping.fbar_grid.FBarPointGrid) against the numpy step
with fempm.stepping.fbar.FBar, its reference.

Both run the same two-body scene (a neo-Hookean body, whose F-bar averages det F, and a linear
elastic one, which averages tr F) from the same state on the same partition (1 or 2 ranks):
positions, velocities, deformation gradients, stresses and volumes agree to round-off after
every scheme, on every cell type of the compiled passes, with lumped, consistent and FMPM mass,
with laws that keep their own numpy stress (the averaged L-bar handed to them), with APIC and
on degree 2.
"""

import numpy as np
import pytest
from mpi4py import MPI

from fempm.materials import LinearElastic
from fempm.materials.newtonian_eos import NewtonianTait
from fempm.stepping import StepOptions
from fempm.stepping import fbar_grid
from fempm.stepping.fbar_grid import FBarPointGrid
from fempm.stepping.grid import SingleFieldGrid

from tests.stepping.test_compiled_step import MESHES, assert_close, make_solver, run_both, state

comm = MPI.COMM_WORLD

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)


class OwnLinearElastic(LinearElastic):
    """A law averaging tr F that keeps its own numpy stress (no compiled kernel for a subclass):
    the compiled grid hands it L-bar = L + (shift / dt) F^-1."""


#: (scheme, mass) pairs, one per cell of DEFAULT in the default run, rotating (each combination
#: a numba compilation of its own on a clean clone; every pair on every cell in make test-all)
PAIRS = [("USL", "lumped"), ("MUSL", "consistent"), ("USF", "fmpm2")]
DEFAULT = ("triangle", "tetrahedron")  # the planar G2P pass and the separate deform pass


@pytest.mark.parametrize(("cell", "scheme", "mass"),
                         [pytest.param(cell, *pair, marks=() if j == i % len(PAIRS) and cell in DEFAULT
                                       else pytest.mark.slow)
                          for i, cell in enumerate(MESHES) for j, pair in enumerate(PAIRS)])
def test_compiled_fbar_equals_the_numpy_fbar(cell, scheme, mass):
    opts = StepOptions(scheme=scheme, flip=0.9, damping=0.5, mass=mass, volumetric="fbar")
    assert isinstance(make_solver(cell, opts).grid, FBarPointGrid)
    ref, got = run_both(cell, opts)
    assert ref[0][1].std() > 0.005  # the particles did move differently
    assert_close(ref, got)


@pytest.mark.parametrize(("cell", "law"), [("triangle", NewtonianTait(rho0=1.0, kappa=30.0, viscosity=0.05)),
                                           ("hexahedron", OwnLinearElastic(40.0, 0.25)),
                                           ("quadrilateral", OwnLinearElastic(40.0, 0.25))],
                         ids=["tait-triangle", "trace-hexahedron", "trace-quadrilateral"])
def test_compiled_fbar_with_a_law_of_its_own(cell, law):
    """The second body's law keeps its own stress (det F averaged for the Tait fluid, tr F for
    the linear elastic subclass): it gets F-bar and L-bar as the numpy step gives them."""
    opts = StepOptions(scheme="USL", flip=0.5, volumetric="fbar")
    ref, got = run_both(cell, opts, law=law)
    assert_close(ref, got)


@pytest.mark.slow
def test_compiled_fbar_with_apic_and_on_degree_2():
    opts = StepOptions(scheme="MUSL", transfer="apic", volumetric="fbar")
    assert_close(*run_both("quadrilateral", opts, steps=10))
    opts = StepOptions(scheme="USL", flip=0.9, mass="lumped", volumetric="fbar", cfl=0.2)
    solver = make_solver("triangle", opts, degree=2, variant="bernstein")
    assert isinstance(solver.grid, FBarPointGrid) and solver.grid.cell.endswith("bernstein2")
    assert_close(*run_both("triangle", opts, steps=8, degree=2, variant="bernstein"))


def test_fbar_takes_the_numpy_step_where_no_compiled_grid_takes_it():
    opts = StepOptions(volumetric="fbar", domain="cpdi1")
    assert isinstance(make_solver("triangle", opts).grid, SingleFieldGrid)
    with pytest.raises(ValueError, match=r"no compiled grid takes these options: FBarPointGrid \(.*\): particle "
                       r"domain cpdi1: point particles$"):
        make_solver("triangle", opts, compiled=True).step()
    assert not isinstance(make_solver("triangle", StepOptions()).grid, FBarPointGrid)


@pytest.mark.parametrize(("cell", "drift_velocity", "width"),
                         [("triangle", (1.5, 0.0), 0.1), ("tetrahedron", (0.0, 0.0, -1.0), 1 / 3),
                          pytest.param("hexahedron", (0.0, 0.0, -1.0), 0.25, marks=pytest.mark.slow)])
def test_the_pressures_summed_in_the_g2p_pass_follow_the_particles_across_cells_and_ranks(monkeypatch, cell,
                                                                                          drift_velocity, width):
    """On triangles the kinematics pass, on tetrahedra and hexahedra the moving pass, also sums the
    next force pass's pressures where each particle ends it; a drift carries the particles across
    cells (and on 2 ranks across ranks, whose departures and arrivals make the force pass sum them
    again): the numpy step to round-off, and the separate pressure pass runs only where the
    particles changed."""
    passes = []
    compiled = fbar_grid.kb.pressure_kernel

    def counted(cell):
        kernel = compiled(cell)

        def run(*args):
            passes.append(len(args[1]))
            return kernel(*args)
        return run

    monkeypatch.setattr(fbar_grid.kb, "pressure_kernel", counted)
    opts = StepOptions(scheme="USL", flip=0.9, damping=0.5, volumetric="fbar")
    out, sizes = [], []
    for compiled_step in (False, True):
        solver = make_solver(cell, opts, compiled=compiled_step)
        solver.particles.fields["v"] = solver.particles.fields["v"] + np.array(drift_velocity)
        axis = int(np.flatnonzero(drift_velocity)[0])
        start = comm.allreduce(float(solver.particles.x[:, axis].sum()))
        sizes.append([len(solver.particles)])
        for _ in range(15):
            solver.step()
            sizes[-1].append(len(solver.particles))
        out.append((state(solver), np.zeros(1), solver.j_range, solver.t))
    assert_close(*out)
    total = comm.allreduce(float(solver.particles.x[:, axis].sum()))
    drift = abs(total - start) / comm.allreduce(len(solver.particles))
    assert drift > 0.3 * width  # a good part of a cell on average
    exchanged = comm.allreduce(int(len(set(sizes[1])) > 1), op=MPI.MAX)  # particles changed ranks
    assert comm.size == 1 or exchanged
    if comm.size == 1:
        assert passes == [len(solver.particles)]  # the first step's force pass alone
    else:
        assert 1 < len(passes) < 16
