"""A rigid collider: a shape (:mod:`fempm.colliders.shapes`) in prescribed translation, with
Coulomb friction against the bodies it touches."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from fempm.colliders.shapes import Shape

__all__ = ["Collider"]


@dataclass(frozen=True)
class Collider:
    """A rigid obstacle: ``shape`` translated with ``velocity``, Coulomb ``friction`` where it
    touches a body (:mod:`fempm.colliders.grid`).

    Args:
        shape: Its signed distance, a :class:`~fempm.colliders.shapes.Shape`
            (:func:`~fempm.colliders.shapes.plane`, :func:`~fempm.colliders.shapes.disk`,
            :func:`~fempm.colliders.shapes.box`, :func:`~fempm.colliders.shapes.polygon`, or one
            of your own with ``dim``, ``distance`` and ``normal_at``), at its position at t = 0.
        velocity: Its velocity, constant (d,) or a callable ``t -> (d,)``; None: at rest.
        friction: The Coulomb coefficient mu >= 0 between it and the bodies.
        gap: How near a node's centre of mass must come to touch it (a length); None: half the
            smallest cell size around the node (over the degree).

    Raises:
        TypeError: A shape without the members of :class:`~fempm.colliders.shapes.Shape`.
        ValueError: A velocity of another dimension than the shape's or not finite, a negative
            or non-finite friction, a gap not > 0.
    """

    shape: Shape
    velocity: npt.ArrayLike | Callable[[float], npt.ArrayLike] | None = None
    friction: float = 0.0
    gap: float | None = None

    def __post_init__(self):
        if not isinstance(self.shape, Shape):
            missing = [m for m in ("dim", "distance", "normal_at") if not hasattr(self.shape, m)]
            raise TypeError(f"a collider's shape needs dim, distance(x) and normal_at(x) (fempm.colliders.shapes.Shape: "
                            f"plane, disk, box, polygon or your own); {type(self.shape).__name__} lacks "
                            f"{', '.join(missing)}")
        if not 0.0 <= self.friction < np.inf:
            raise ValueError(f"a collider needs a finite friction coefficient mu >= 0 (got {self.friction!r})")
        if self.gap is not None and not 0.0 < self.gap < np.inf:
            raise ValueError(f"a collider needs a finite gap > 0 or None (got {self.gap!r})")
        if not callable(self.velocity):
            self.velocity_at(0.0)

    @property
    def dim(self) -> int:
        """The dimension of its shape."""
        return self.shape.dim

    def velocity_at(self, t: float) -> npt.NDArray:
        """Its velocity (d,) at time ``t``.

        Raises:
            ValueError: A velocity (given or returned) of the wrong shape or not finite.
        """
        if self.velocity is None:
            return np.zeros(self.dim)
        u = np.asarray(self.velocity(t) if callable(self.velocity) else self.velocity, dtype=np.float64)
        if u.shape != (self.dim,) or not np.all(np.isfinite(u)):
            raise ValueError(f"a collider's velocity must be {self.dim} finite numbers (got {u!r} at t = {t:g})")
        return u
