r"""The shapes of rigid colliders, given by their signed distance.

A shape :math:`S` is its signed distance :math:`\phi(x)`: the distance to its surface,
positive outside :math:`S` (where a body may be) and negative inside, and its outward normal
:math:`\nabla\phi(x)` (unit), evaluated at points x of shape (k, d):

* :func:`plane` (the half-space behind a plane), :math:`\phi = (x - p) \cdot n`;
* :func:`disk` (a sphere in 3D), :math:`\phi = |x - c| - r`;
* :func:`box` (axis-aligned), :math:`\phi = |\max(q, 0)| + \min(\max_a q_a, 0)`,
  :math:`q = |x - c| - h` for the centre :math:`c` and half-sizes :math:`h`;
* :func:`polygon` (2D), the distance to the nearest edge, negative inside (even-odd rule).

Any object with these three members is a shape (:class:`Shape`, a protocol checked at run
time): a user's own, e.g. a cylinder's end cap or a level set read from a file, collides as
the built-in ones do (docs/architecture.md, "A collider shape of your own").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

__all__ = ["Box", "Disk", "Plane", "Polygon", "Shape", "box", "disk", "plane", "polygon"]


@runtime_checkable
class Shape(Protocol):
    """What a collider needs of its shape, at its position at t = 0 (the collider moves it).

    Attributes:
        dim: The space dimension (2 or 3).
    """

    @property
    def dim(self) -> int: ...

    def distance(self, x: npt.NDArray) -> npt.NDArray:
        """The signed distance (k,) of points ``x`` (k, dim): positive outside the shape."""

    def normal_at(self, x: npt.NDArray) -> npt.NDArray:
        """The outward unit normals (k, dim), the gradient of :meth:`distance`, at ``x``."""


def _point(value, what: str, dims: tuple[int, ...] = (2, 3)) -> npt.NDArray:
    x = np.asarray(value, dtype=np.float64)
    if x.ndim != 1 or len(x) not in dims or not np.all(np.isfinite(x)):
        raise ValueError(f"{what} must be {' or '.join(map(str, dims))} finite numbers (got {value!r})")
    return x


def _unit(x: npt.NDArray) -> npt.NDArray:
    """The rows of ``x`` scaled to unit length (the first axis where a row is 0)."""
    length = np.linalg.norm(x, axis=1)
    out = np.zeros_like(x)
    out[:, 0] = 1.0
    some = length > 0
    out[some] = x[some] / length[some, None]
    return out


@dataclass(frozen=True)
class Plane:
    """The half-space behind the plane through ``point`` with unit outward ``normal``."""

    point: npt.NDArray
    normal: npt.NDArray

    @property
    def dim(self) -> int:
        return len(self.point)

    def distance(self, x: npt.NDArray) -> npt.NDArray:
        return (x - self.point) @ self.normal

    def normal_at(self, x: npt.NDArray) -> npt.NDArray:
        return np.broadcast_to(self.normal, x.shape)


@dataclass(frozen=True)
class Disk:
    """The disk (sphere in 3D) of ``centre`` and ``radius``."""

    centre: npt.NDArray
    radius: float

    @property
    def dim(self) -> int:
        return len(self.centre)

    def distance(self, x: npt.NDArray) -> npt.NDArray:
        return np.linalg.norm(x - self.centre, axis=1) - self.radius

    def normal_at(self, x: npt.NDArray) -> npt.NDArray:
        return _unit(x - self.centre)


@dataclass(frozen=True)
class Box:
    """The axis-aligned box ``[lo, hi]``."""

    lo: npt.NDArray
    hi: npt.NDArray

    @property
    def dim(self) -> int:
        return len(self.lo)

    def _q(self, x: npt.NDArray) -> tuple[npt.NDArray, npt.NDArray]:
        r = x - 0.5 * (self.lo + self.hi)
        return r, np.abs(r) - 0.5 * (self.hi - self.lo)

    def distance(self, x: npt.NDArray) -> npt.NDArray:
        _, q = self._q(x)
        return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)

    def normal_at(self, x: npt.NDArray) -> npt.NDArray:
        r, q = self._q(x)
        sign = np.where(r < 0, -1.0, 1.0)
        outside = q.max(axis=1) > 0
        n = sign * np.maximum(q, 0.0)  # outside: towards the nearest point of the box
        inside = np.zeros_like(q)  # inside: the axis of the nearest face
        inside[np.arange(len(q)), np.argmax(q, axis=1)] = 1.0
        return _unit(np.where(outside[:, None], n, sign * inside))


@dataclass(frozen=True)
class Polygon:
    """The simple polygon with the vertices ``points`` (k, 2), in order."""

    points: npt.NDArray

    dim = 2

    def _nearest(self, x: npt.NDArray) -> tuple[npt.NDArray, npt.NDArray]:
        """(signed distance, the vector from the nearest surface point to x)."""
        a = self.points
        b = np.roll(a, -1, axis=0)
        e = b - a  # (m, 2)
        ax = x[:, None, :] - a[None]  # (k, m, 2)
        s = np.clip(np.einsum("kmd,md->km", ax, e) / np.einsum("md,md->m", e, e), 0.0, 1.0)
        r = ax - s[..., None] * e  # from the nearest point of each edge to x
        d2 = np.einsum("kmd,kmd->km", r, r)
        nearest = np.argmin(d2, axis=1)
        k = np.arange(len(x))
        # even-odd rule: crossings of the ray from x along +x
        ya, yb = a[None, :, 1], b[None, :, 1]
        straddles = (ya > x[:, 1:2]) != (yb > x[:, 1:2])
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = a[None, :, 0] + (x[:, 1:2] - ya) * (b[None, :, 0] - a[None, :, 0]) / (yb - ya)
        inside = np.count_nonzero(straddles & (x[:, :1] < xc), axis=1) % 2 == 1
        sign = np.where(inside, -1.0, 1.0)
        return sign * np.sqrt(d2[k, nearest]), sign[:, None] * r[k, nearest]

    def distance(self, x: npt.NDArray) -> npt.NDArray:
        return self._nearest(x)[0]

    def normal_at(self, x: npt.NDArray) -> npt.NDArray:
        return _unit(self._nearest(x)[1])


def plane(point, normal) -> Plane:
    """The half-space behind a plane (a line in 2D): the collider fills the side opposite ``normal``.

    Args:
        point: A point of the plane (d,).
        normal: Its normal (d,), any length but not zero, pointing out of the collider.

    Raises:
        ValueError: A zero or non-finite normal, or point and normal of different dimensions.
    """
    p = _point(point, "a plane's point")
    n = np.asarray(normal, dtype=np.float64)
    if n.shape != p.shape or not np.all(np.isfinite(n)) or not np.linalg.norm(n) > 0:
        raise ValueError(f"a collider plane needs a finite, non-zero normal with {len(p)} components (got {normal!r})")
    return Plane(p, n / np.linalg.norm(n))


def disk(centre, radius: float) -> Disk:
    """A disk of ``centre`` (2,) and ``radius``, or a sphere with a centre (3,).

    Raises:
        ValueError: A radius that is not a finite number > 0.
    """
    c = _point(centre, "a disk's centre")
    if not 0.0 < radius < np.inf:
        raise ValueError(f"a collider disk needs a finite radius > 0 (got {radius!r})")
    return Disk(c, float(radius))


def box(lo, hi) -> Box:
    """The axis-aligned box with the corners ``lo`` and ``hi`` (d,).

    Raises:
        ValueError: ``lo`` not below ``hi`` in every component.
    """
    a, b = _point(lo, "a box's lower corner"), _point(hi, "a box's upper corner")
    if a.shape != b.shape or not np.all(a < b):
        raise ValueError(f"a collider box needs lo < hi in every component (got lo={lo!r}, hi={hi!r})")
    return Box(a, b)


def polygon(points) -> Polygon:
    """The simple polygon (2D) through ``points`` (k >= 3, 2), in either order.

    Raises:
        ValueError: Fewer than 3 points, non-finite ones, or no area.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or len(p) < 3 or not np.all(np.isfinite(p)):
        raise ValueError(f"a collider polygon needs 3 or more finite points in 2D, shape (k, 2) (got shape {p.shape})")
    x, y = p.T
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    scale = np.ptp(p, axis=0).max()
    if not area > 1e-12 * scale**2:
        raise ValueError("a collider polygon needs points that enclose an area (these are on one line)")
    return Polygon(p)
