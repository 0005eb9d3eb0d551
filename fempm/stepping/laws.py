"""Calling the material laws on the particles of their bodies: the state of their internal
variables and the checked stress update."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from fempm.abort import raise_together

__all__ = ["every", "law_state", "law_stress", "material_groups", "stresses_of"]


def law_state(mat, fields: dict, idx: npt.NDArray) -> dict:
    """The internal variables of law ``mat`` at the particles ``idx`` (copies), by name."""
    return {h.name: fields[h.name][idx] for h in mat.history}


def law_stress(mat, F: npt.NDArray, L: npt.NDArray, sigma: npt.NDArray, dt: float, rho: npt.NDArray,
               fields: dict, idx: npt.NDArray) -> npt.NDArray:
    """``mat.stress(F, L, sigma, dt, rho)`` of the particles ``idx`` (and, for a law with
    internal variables, their ``state`` from ``fields``, updated there), checked to be one
    (d, d) stress per particle."""
    history = mat.history
    if history:
        state = law_state(mat, fields, idx)
        new = np.asarray(mat.stress(F, L, sigma, dt, rho, state))
        for h in history:
            fields[h.name][idx] = state[h.name]
    else:
        new = np.asarray(mat.stress(F, L, sigma, dt, rho))
    if new.shape != sigma.shape:
        raise ValueError(f"{type(mat).__name__}.stress returned an array of shape {new.shape} for {len(F)} "
                         f"particle(s); expected {sigma.shape}")
    return new


def stresses_of(comm, groups, F: npt.NDArray, L: npt.NDArray, sigma: npt.NDArray, dt: float, rho: npt.NDArray,
                fields: dict) -> None:
    """The laws' stress of the particles of each (law, indices) of ``groups`` into ``sigma``
    (:func:`law_stress`). A law that raises on some ranks only (a user's law, a particle
    state one rank holds) is raised on every rank (:func:`fempm.abort.raise_together`), so
    that no rank waits for ever in the step's next collective. Collective."""
    error = None
    try:
        for mat, idx in groups:
            at = every(idx, len(sigma))
            sigma[idx] = law_stress(mat, F[at], L[at], sigma[at], dt, rho[at], fields, idx)
    except Exception as e:  # noqa: BLE001 - whatever the law raised, on every rank
        error = e
    raise_together(comm, error)


def every(idx: npt.NDArray, n: int) -> npt.NDArray | slice:
    """``idx``, or ``slice(None)`` where it holds all ``n`` particles (a law of every particle
    reads their arrays as they are: views, not copies)."""
    return slice(None) if len(idx) == n else idx


def material_groups(fields: dict, materials: Sequence):
    """(law, indices of its particles) for each law of ``materials``, by the particles' body
    index ``fields["body"]``."""
    body = fields["body"]
    for b, mat in enumerate(materials):
        yield mat, np.flatnonzero(body == b)
