"""Hydrostatic column (docs/verification.md): gravity, slip walls along two normals,
PIC damping to rest; sigma_yy = -rho g (H - Y), base value -rho g H = -1765.8 Pa."""

import dolfinx.mesh as dm
import fempm
import numpy as np
import pytest
from mpi4py import MPI

from fempm.boundary import slip
from fempm.materials import LinearElastic
from fempm.scene import Scene, run
from fempm.stepping import Loads, StepOptions

pytestmark = pytest.mark.parallel  # also under mpiexec -n 2 (scripts/run-tests)


def test_hydrostatic_column_base_stress():
    comm = MPI.COMM_WORLD
    rho, g, H, W, E = 1800.0, 9.81, 0.1, 0.05, 1e6
    h = H / 8
    mesh = dm.create_rectangle(comm, [[0, 0], [W, H + 2 * h]], [4, 10], dm.CellType.quadrilateral)
    p = fempm.create_particles(mesh, 4, density=rho, cells=lambda x: x[1] < H)
    p.fields["Y"] = p.x[:, 1].copy()

    def bcs(V):
        return [slip(V, lambda x: np.isclose(x[0], 0) | np.isclose(x[0], W), (1.0, 0.0)),
                slip(V, lambda x: np.isclose(x[1], 0), (0.0, 1.0))]

    scene = Scene("column", mesh, p, [LinearElastic(E, 0.0)], t_end=0.3, loads=Loads(body_force=(0.0, -g)),
                  bcs=bcs, options=StepOptions(flip=0.0, cfl=0.4))
    r = run(scene, None, progress=False)
    assert r["terms_assembled"] == {"internal": r["steps"], "body_force": r["steps"]}
    Y = np.concatenate(comm.allgather(p.fields["Y"]))
    syy = np.concatenate(comm.allgather(p.fields["sigma"][:, 1, 1]))
    slope, base = np.polyfit(Y, syy, 1)
    assert base == pytest.approx(-rho * g * H, rel=5e-3)  # measured: -1763.5 Pa
    assert slope == pytest.approx(rho * g, rel=2e-2)
    assert comm.allreduce(np.abs(p.fields["v"]).max(initial=0.0), op=MPI.MAX) < 1e-3  # at rest
