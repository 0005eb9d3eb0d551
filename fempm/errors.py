"""Error norms of projected fields, reduced over ranks."""

from __future__ import annotations

import dolfinx.fem
import numpy as np
import ufl
from mpi4py import MPI


def l2_error(uh: dolfinx.fem.Function, exact) -> float:
    r""":math:`\|u_h - u\|_{L^2}` with ``exact`` a UFL expression (use
    ``ufl.SpatialCoordinate``) or a Function; integrated with a raised quadrature degree."""
    mesh = uh.function_space.mesh
    deg = uh.function_space.element.basix_element.degree + 4
    e = uh - exact
    form = dolfinx.fem.form(ufl.inner(e, e) * ufl.dx(metadata={"quadrature_degree": deg}))
    return float(np.sqrt(mesh.comm.allreduce(dolfinx.fem.assemble_scalar(form), op=MPI.SUM)))
