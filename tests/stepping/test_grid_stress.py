"""Grid stress (``ExplicitSolver.grid_stress``): stress is projected as a per-volume field,
so the grid stress does not depend on the particles' densities (the density-ratio
kernel), on 1 and 2 ranks, with point and CPDI2 domains; a mass-weighted map would lean towards
the heavy side of a density jump."""

import dolfinx.fem as fem
import dolfinx.mesh as dm
import fempm
import numpy as np
import pytest
from mpi4py import MPI

from fempm.materials import LinearElastic
from fempm.stepping.diagnostics import stress_space
from fempm.stepping import ExplicitSolver, StepOptions
from fempm.transfer import Projector

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD


def stress_field(x):
    """A smooth, not linear, stress field (n, 2, 2): a least-squares fit depends on its weights."""
    s = np.empty((len(x), 2, 2))
    s[:, 0, 0] = 1.0 + np.sin(3.0 * x[:, 0])
    s[:, 1, 1] = -0.5 + x[:, 1]
    s[:, 0, 1] = s[:, 1, 0] = 0.3 * x[:, 0] - x[:, 1]
    return s


@pytest.mark.parametrize("domain", ["point", "cpdi2"])
@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_grid_stress_is_independent_of_density(domain, mass):
    mesh = dm.create_unit_square(comm, 8, 8, dm.CellType.quadrilateral)
    V = fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    out = {}
    for name, rho in (("uniform", lambda x: np.ones(len(x))), ("jump", lambda x: np.where(x[:, 0] < 0.5, 1.0, 100.0))):
        p = fempm.create_particles(mesh, 4, density=rho, corners=domain == "cpdi2")
        p.fields["sigma"] = stress_field(p.x)
        solver = ExplicitSolver(V, p, [LinearElastic(1.0, 0.3)], options=StepOptions(domain=domain))
        out[name] = solver.grid_stress(mass=mass).x.array.copy()
        if name == "jump":  # the mass-weighted map of the same data does depend on the density
            mw = Projector(stress_space(V), p, mass=mass, domain=solver.options.particle_domain)
            out["mass-weighted"] = mw.project(p.fields["sigma"].reshape(len(p), 4)).x.array.copy()
    same = comm.allreduce(np.abs(out["jump"] - out["uniform"]).max(), op=MPI.MAX)
    biased = comm.allreduce(np.abs(out["mass-weighted"] - out["uniform"]).max(), op=MPI.MAX)
    assert same < 1e-10  # measured 0 (the weights are the same volumes)
    assert biased > 1e-5  # measured 5.8e-5 (consistent), 1.4e-2 (lumped)
