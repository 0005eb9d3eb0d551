r"""External loads of the explicit step: body forces and particle tractions.

A body force is per unit mass, :math:`f_i \mathrel{+}= \sum_p M_p b_p N_{ip}`; a traction acts on
the particles that carry a loaded surface, :math:`f_i \mathrel{+}= \sum_p \bar t_p A_p N_{ip}`
with :math:`A_p` the particle's share of that surface.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt


@dataclass
class Loads:
    r"""External loads; a term left None is never assembled.

    body_force: acceleration (d,), or a function of the current positions ``x`` (n, d) and the
    time ``t``, ``f(x, t)``, or also of the reference positions ``X`` (n, d), ``f(x, t, X)``
    (the particles' ``fields["X0"]``, e.g. a manufactured body force :math:`b(X, t)`); it
    returns (n, d), per unit mass. The number of positional parameters decides which is called.

    traction: a function t -> (n, d), the traction :math:`\bar t_p` on each particle (zero rows
    away from the loaded surface), applied as the force :math:`\bar t_p A_p` where :math:`A_p`
    is the particle's share of the loaded surface: ``fields["area"]`` when the particles carry
    it (e.g. from :func:`surface_areas`), else :math:`(V^0_p)^{(d-1)/d}`, the face of a cubic
    particle (exact for a layer of square/cubic particles on a flat face, at any number of
    particles per cell).
    """

    body_force: npt.ArrayLike | Callable | None = None
    traction: Callable[[float], npt.NDArray] | None = None


def takes_reference_positions(fn: Callable) -> bool:
    """Whether a body-force callable takes ``(x, t, X)`` (three positional parameters) rather
    than ``(x, t)``."""
    try:
        params = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):  # builtins without a signature: the (x, t) form
        return False
    if any(p.kind == p.VAR_POSITIONAL for p in params):
        return True
    positional = [p for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    return len(positional) >= 3


def surface_areas(volumes: npt.NDArray, loaded: npt.NDArray[np.bool_], measure: float, comm) -> npt.NDArray:
    r"""Each loaded particle's share :math:`A_p = |\Gamma|\, V_p / \sum_{q\ loaded} V_q` of a
    loaded surface of measure ``measure`` (length in 2D, area in 3D), 0 elsewhere, so that a
    uniform traction :math:`\bar t` applies exactly the total force :math:`\bar t |\Gamma|`
    (collective: the sum runs over all ranks)."""
    total = comm.allreduce(float(np.sum(volumes[loaded])))
    if total <= 0:
        raise ValueError("no particle carries the loaded surface")
    return np.where(loaded, measure * volumes / total, 0.0)


def body_force_at(b, particles, t: float) -> npt.NDArray:
    """The body force per unit mass at the particles (n, d): ``b`` a constant (d,) or a callable
    ``(x, t)`` / ``(x, t, X)`` (see :class:`Loads`); a wrong shape is a ValueError."""
    if not callable(b):
        b = np.asarray(b, float)
        if b.shape != (particles.gdim,):
            raise ValueError(f"the body force has shape {b.shape}, expected ({particles.gdim},)")
        return np.broadcast_to(b, particles.x.shape)
    if takes_reference_positions(b):
        acc = b(particles.x, t, particles.fields["X0"])
    else:
        acc = b(particles.x, t)
    acc = np.asarray(acc, dtype=np.float64)
    if acc.shape != particles.x.shape:
        raise ValueError(f"the body force returned shape {acc.shape} for {len(particles)} particles in "
                         f"{particles.gdim}D (expected {particles.x.shape})")
    return acc


def surface_shares(particles) -> npt.NDArray:
    """The particles' shares of the loaded surface: ``fields["area"]``, else the face
    :math:`(V^0_p)^{(d-1)/d}` of a square/cubic particle (see :class:`Loads`)."""
    f = particles.fields
    if "area" in f:
        return f["area"]
    d = particles.gdim
    return f["volume0"] ** ((d - 1) / d)


def external_forces(loads, particles, t: float) -> npt.NDArray:
    r"""The external force on each particle (n, d) at time ``t``:
    :math:`f^{ext}_p = M_p b_p + \bar t_p A_p` (the terms ``loads`` declares; zeros without any)."""
    p = particles
    f = np.zeros((len(p), p.gdim))
    if loads.body_force is not None:
        f += p.mass[:, None] * body_force_at(loads.body_force, p, t)
    if loads.traction is not None:
        traction = np.asarray(loads.traction(t), dtype=np.float64)
        if traction.shape != f.shape:
            raise ValueError(f"the traction returned shape {traction.shape} for {len(p)} particles in {p.gdim}D "
                             f"(expected {f.shape})")
        f += traction * surface_shares(p)[:, None]
    return f
