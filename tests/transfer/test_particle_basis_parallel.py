"""Particle basis functions as DOLFINx Functions on 1 and 2 ranks: the same functions
(compared through their integrals), and their sum over all particles is 1."""

import dolfinx.fem as fem
import dolfinx.mesh as dm
import numpy as np
import pytest
import ufl
from mpi4py import MPI

import fempm
from fempm.transfer.domains import GIMP
from fempm.transfer.particle_basis import particle_basis_functions

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)

comm = MPI.COMM_WORLD


def integrals(c, option):
    mesh = dm.create_unit_square(c, 8, 8, dm.CellType.quadrilateral)
    p = fempm.create_particles(mesh, 4, density=1.0, jitter=0.3, seed=5, where=lambda x: x[0] + x[1] < 1.4)
    V = fem.functionspace(mesh, ("Lagrange", 1))
    funcs = particle_basis_functions(V, p, [7, 40, 101], option=option, domain=GIMP(2))
    out = [c.allreduce(fem.assemble_scalar(fem.form(f * ufl.dx)), op=MPI.SUM) for f in funcs]
    out += [c.allreduce(fem.assemble_scalar(fem.form(f * f * ufl.dx)), op=MPI.SUM) for f in funcs]
    ones = fempm.Projector(V, p, mass=option, domain=GIMP(2)).project(np.ones(len(p)))
    act = np.abs(ones.x.array) > 0
    pu = c.allreduce(np.abs(ones.x.array[act] - 1).max(initial=0.0), op=MPI.MAX)
    return np.array(out), pu


@pytest.mark.parametrize("option", ["lumped", "consistent"])
def test_particle_basis_functions_parallel_equal_serial(option):
    world, pu = integrals(comm, option)
    serial, _ = integrals(MPI.COMM_SELF, option)
    np.testing.assert_allclose(world, serial, rtol=1e-9)
    assert np.all(world[:3] > 0)
    assert pu < 1e-10  # sum_p Phi_p = 1 on the supported dofs
