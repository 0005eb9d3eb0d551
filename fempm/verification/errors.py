"""Error norms of projected fields, reduced over ranks."""

from __future__ import annotations

import dolfinx.fem
import numpy as np
import ufl
from mpi4py import MPI

__all__ = ["ErrorHistory", "l2_error", "particle_errors"]


def l2_error(uh: dolfinx.fem.Function, exact) -> float:
    r""":math:`\|u_h - u\|_{L^2}` with ``exact`` a UFL expression (use
    ``ufl.SpatialCoordinate``) or a Function; integrated with a raised quadrature degree."""
    mesh = uh.function_space.mesh
    deg = uh.function_space.element.basix_element.degree + 4
    e = uh - exact
    form = dolfinx.fem.form(ufl.inner(e, e) * ufl.dx(metadata={"quadrature_degree": deg}))
    return float(np.sqrt(mesh.comm.allreduce(dolfinx.fem.assemble_scalar(form), op=MPI.SUM)))


def particle_errors(particles, exact, t: float) -> dict[str, float]:
    r"""Displacement errors of the particles against an exact motion at time ``t``.

    With :math:`u_p = x_p - X_p` and :math:`e_p = |u_p - u(X_p, t)|`:

    * ``max``: :math:`\max_p e_p`,
    * ``rms``: :math:`\sqrt{\sum_p e_p^2 / N}`,
    * ``l2``: :math:`\sqrt{\sum_p V^0_p e_p^2}`, an :math:`L^2` norm over the reference body.

    Args:
        particles: The particles, with the reference positions ``fields["X0"]`` and volumes
            ``fields["volume0"]``.
        exact: Any object with ``displacement(X, t)`` (:mod:`fempm.verification.manufactured`).
        t: The time.

    Returns:
        ``{"max": ..., "rms": ..., "l2": ...}``, the same on every rank.

    Note:
        Collective.
    """
    X = particles.fields["X0"]
    e = np.linalg.norm(particles.x - X - exact.displacement(X, t), axis=1) if len(X) else np.zeros(0)
    comm = particles.comm
    emax = comm.allreduce(float(e.max(initial=0.0)), op=MPI.MAX)
    sq, wsq, n = comm.allreduce(np.array([np.sum(e**2), np.sum(particles.fields["volume0"] * e**2), len(e)]))
    return {"max": emax, "rms": float(np.sqrt(sq / max(n, 1))), "l2": float(np.sqrt(wsq))}


class ErrorHistory:
    """Particle errors (:func:`particle_errors`) after every step of a run, with their maxima
    over time; use as ``run(scene, callback=history)`` (the initial state is recorded when the
    history is made, ``ErrorHistory(exact, particles)``)."""

    def __init__(self, exact, particles=None):
        self.exact = exact
        self.rows: list[dict[str, float]] = []
        self.worst = {"max": 0.0, "rms": 0.0, "l2": 0.0}
        if particles is not None:
            self.record(particles, 0.0)

    def record(self, particles, t: float) -> dict[str, float]:
        err = particle_errors(particles, self.exact, t)
        self.rows.append({"t": t, **err})
        self.worst = {k: max(self.worst[k], v) for k, v in err.items()}
        return err

    def __call__(self, solver) -> None:
        self.record(solver.particles, solver.t)
