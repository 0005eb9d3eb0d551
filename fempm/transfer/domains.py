r"""Particle domains: where the basis is averaged (docs/particle_basis.md).

A domain turns each particle into sample points :math:`y_{pq}` with value weights
:math:`w_{pq}` (:math:`\sum_q w_{pq} = 1`) and gradient weights, so that

.. math::
    v_{ip} = \langle N_i \rangle_p = \sum_q w_{pq} N_i(y_{pq}), \qquad
    \langle \nabla N_i \rangle_p = \sum_q \big( w_{pq} \nabla N_i(y_{pq})
        + N_i(y_{pq})\, g_{pq} \big).

* :class:`Point`: standard MPM, :math:`y_p = x_p`, :math:`w = 1`.
* :class:`GIMP`: the average over the particle's axis-aligned box (half-widths
  :math:`\ell = \tfrac12 V_0^{1/d}` per axis; uGIMP keeps them, cpGIMP stretches them by the
  diagonal of :math:`F`, ``deform=True``), integrated exactly over the box's pieces in the
  mesh cells (:mod:`fempm.transfer.box_average`), or, with an integer ``order``, by a tensor
  Gauss-Legendre rule of ``order`` points per direction (inexact where the box straddles a
  grid line); :math:`\langle \nabla N_i \rangle_p = |\Omega_p|^{-1} \int_{\Omega_p} \nabla N_i`.
* :class:`CPDI1`: the parallelogram (parallelepiped) :math:`x_p + R \xi`,
  :math:`\xi \in [-1, 1]^d`, :math:`R = F R_0`, :math:`R_0 = \operatorname{diag}(\ell)`; the grid basis is replaced by
  its multilinear interpolant between the :math:`2^d` corners :math:`c = x_p + R s`,
  :math:`s \in \{\pm 1\}^d` (Sadeghirad, Brannon and Burghardt 2011): :math:`w_c = 2^{-d}`,
  :math:`g_c = 2^{-d} R^{-T} s` (the average of the corner function's gradient), and no
  :math:`\nabla N` term.
* :class:`CPDI2`: domains tracked by their corners ``fields["corners"]``, simplices
  (n, d + 1, d) or quadrilaterals / hexahedra (n, 2^d, d), moved with the grid velocity: the
  basis is replaced by its (multi)linear interpolant between the corners,
  :math:`w_c = |\Omega_p|^{-1} \int_{\Omega_p} \phi_c`,
  :math:`g_c = |\Omega_p|^{-1} \int_{\Omega_p} \nabla \phi_c` (Sadeghirad, Brannon and
  Guilkey 2013); for simplices :math:`w_c = 1 / (d + 1)`, :math:`g_c = \nabla \lambda_c`.

Averaged bases keep the partition of unity exactly; for affine cells they reproduce linear
fields (:math:`\sum_i \langle N_i \rangle_p x_i = x_p` for a domain centred at :math:`x_p`, and
:math:`\sum_i x_i \otimes \langle \nabla N_i \rangle_p = I`) for domains inside the mesh.

Domains at the mesh boundary: the part of a domain beyond the mesh is cut off. GIMP boxes are
truncated and the average is taken over the part inside,
:math:`\langle N_i \rangle_p = |\Omega_p \cap \Omega_h|^{-1} \int_{\Omega_p \cap \Omega_h} N_i`
(Gauss-rule GIMP drops its points outside and renormalises the weights); CPDI corners outside
the mesh are moved to the closest point of the mesh, which cuts a domain off along the boundary
(exactly so for the part of a box beyond a straight wall parallel to its sides). Both keep the
partition of unity and :math:`\sum_i \langle \nabla N_i \rangle_p = 0`, hence the
conservation of mass and momentum, with the particle's mass and volume unchanged; the averaged
basis then reproduces the centroid of the cut domain instead of :math:`x_p`. This is the
truncation that keeps the particle's mass on the nodes of the mesh, rather than on nodes of a
layer of extra cells beyond the boundary (Uintah's extra cells, NairnMPM's extra elements),
which a DOLFINx mesh does not have.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from fempm.particles.corners import corner_signs, domain_geometry
from fempm.particles.particle_set import Particles

__all__ = [
    "CPDI1", "CPDI2", "DOMAINS", "GIMP", "GIMP_NAMES", "Domain", "Point", "Samples", "half_widths",
    "make_domain", "step_domain",
]


@dataclass
class Samples:
    """Sample points of the particle domains: ``x`` (n, q, d), value weights ``w`` (n, q),
    optional vector gradient weights ``g`` (n, q, d) (multiplying :math:`N_i(y)`), whether
    the value weights also weight :math:`\\nabla N_i(y)` (``grad_from_values``), and what
    happens to points beyond the mesh (``beyond``): ``"clamp"`` evaluates them at the closest
    point of the mesh, ``"cut"`` drops them and renormalises the particle's weights."""

    x: npt.NDArray
    w: npt.NDArray
    g: npt.NDArray | None = None
    grad_from_values: bool = True
    beyond: str = "clamp"


def half_widths(particles: Particles, deform: bool = False) -> npt.NDArray:
    r"""Box half-widths (n, d): ``fields["lp"]`` when the particles carry them (e.g. the half
    sizes of their seeding sub-cells), else :math:`\tfrac12 V_0^{1/d}` (``fields["volume0"]`` or
    the current volume); times :math:`F_{aa}` per axis with ``deform``."""
    d = particles.gdim
    if "lp" in particles.fields:
        ell = np.array(particles.fields["lp"], dtype=np.float64).reshape(len(particles), d)
    else:
        V0 = particles.fields.get("volume0", particles.volume)
        ell = np.repeat((0.5 * V0 ** (1.0 / d))[:, None], d, axis=1)
    if deform and "F" in particles.fields:
        ell = ell * np.abs(np.einsum("nii->ni", particles.fields["F"]))
    return ell


class Domain:
    """What every particle domain declares: its samples (:meth:`samples`), whether it is tracked
    by its corners, and how it moves."""

    #: whether the domain is tracked by its corners (``fields["corners"]``), moved with the grid
    #: velocity; the particle then sits at its domain's centroid
    tracks_corners: ClassVar[bool] = False

    def samples(self, particles: Particles) -> Samples:
        """The domain's sample points and weights (:class:`Samples`)."""
        raise NotImplementedError

    def move(self, particles: Particles, at_grid: npt.NDArray, corner_velocity: Callable[[], npt.NDArray], dt: float,
             by_particle_velocity: bool = False) -> None:
        r"""Move the particles over ``dt``: :math:`x_p^+ = x_p + \Delta t\, u_p` with the grid
        velocity at them ``at_grid`` (or their own updated velocity, ``by_particle_velocity``).
        ``corner_velocity()``: the grid velocity at the domains' corners (n, corners, d), for
        domains tracked by their corners."""
        particles.x = particles.x + dt * (particles.fields["v"] if by_particle_velocity else at_grid)


@dataclass(frozen=True)
class Point(Domain):
    """Standard MPM: the particle is a point."""

    name: str = "point"

    def samples(self, particles: Particles) -> Samples:
        n = len(particles)
        return Samples(particles.x[:, None, :].copy(), np.ones((n, 1)))


@dataclass(frozen=True)
class GIMP(Domain):
    """Average over the particle's axis-aligned box: exact (``order=None``, the default) or by a
    tensor Gauss rule of ``order`` points per axis; ``deform`` stretches the box by diag(F)
    (cpGIMP) instead of keeping its initial size (uGIMP)."""

    order: int | None = None
    deform: bool = False
    name: str = "gimp"
    def __post_init__(self):
        if self.order is not None and self.order < 1:
            raise ValueError(f"GIMP order must be >= 1 or None (exact) (got {self.order})")

    @property
    def exact(self) -> bool:
        return self.order is None

    def box(self, particles: Particles) -> tuple[npt.NDArray, npt.NDArray]:
        """Lower and upper corners (n, d) of the particles' boxes."""
        ell = half_widths(particles, self.deform)
        return particles.x - ell, particles.x + ell

    def samples(self, particles: Particles) -> Samples:
        if self.exact:
            raise ValueError("exact GIMP integrates over box pieces (fempm.transfer.box_average), it has no sample points")
        d = particles.gdim
        xi, wi = np.polynomial.legendre.leggauss(self.order)
        pts = np.array(list(itertools.product(xi, repeat=d)))  # (q, d) in [-1, 1]^d
        wts = np.prod(np.array(list(itertools.product(wi, repeat=d))), axis=1) / 2**d
        ell = half_widths(particles, self.deform)
        x = particles.x[:, None, :] + pts[None, :, :] * ell[:, None, :]
        return Samples(x, np.broadcast_to(wts, (len(particles), len(wts))).copy(), beyond="cut")


@dataclass(frozen=True)
class CPDI1(Domain):
    """Parallelogram / parallelepiped domains that follow F (corner interpolation)."""

    name: str = "cpdi1"

    def vectors(self, particles: Particles) -> npt.NDArray:
        """Half-edge vectors as columns, :math:`R = F \\operatorname{diag}(\\ell)` (n, d, d)."""
        d = particles.gdim
        ell = half_widths(particles)
        F = particles.fields.get("F", np.broadcast_to(np.eye(d), (len(particles), d, d)))
        return F * ell[:, None, :]

    def samples(self, particles: Particles) -> Samples:
        d = particles.gdim
        s = corner_signs(d)
        R = self.vectors(particles)
        x = particles.x[:, None, :] + np.einsum("nij,qj->nqi", R, s)
        Rinv_T = np.swapaxes(np.linalg.inv(R), 1, 2)
        g = np.einsum("nij,qj->nqi", Rinv_T, s) / 2**d
        w = np.full((len(particles), 2**d), 1.0 / 2**d)
        return Samples(x, w, g, grad_from_values=False)


@dataclass(frozen=True)
class CPDI2(Domain):
    """Domains tracked by their corners ``fields["corners"]`` (n, k, d): simplices (k = d + 1)
    or quadrilaterals / hexahedra (k = 2^d), moved with the grid velocity."""

    name: str = "cpdi2"
    tracks_corners: ClassVar[bool] = True

    @staticmethod
    def corners(particles: Particles) -> npt.NDArray:
        if "corners" not in particles.fields:
            raise ValueError("CPDI2 needs particle corners: fields['corners'] of shape (n, k, d) "
                             "(create_particles(..., corners=True) or fempm.transfer.domains.box_corners set them)")
        c = particles.fields["corners"]
        if c.ndim != 3 or c.shape[0] != len(particles) or c.shape[2] != particles.gdim:
            raise ValueError(f"CPDI2 corners must have shape (n, k, {particles.gdim}), got {c.shape}")
        return c

    def samples(self, particles: Particles) -> Samples:
        c = self.corners(particles)
        w, g, _, _ = domain_geometry(c, particles.comm)
        return Samples(c.copy(), w, g, grad_from_values=False)

    def move(self, particles: Particles, at_grid: npt.NDArray, corner_velocity: Callable[[], npt.NDArray], dt: float,
             by_particle_velocity: bool = False) -> None:
        r"""Corners :math:`y_c^+ = y_c + \Delta t\, u_c` with the grid velocity at them; the
        particle moves to its domain's centroid and takes its volume (for simplices the centroid
        moves by :math:`\Delta t \sum_i \langle N_i \rangle_p v_i^+` and
        :math:`|\Omega_p| = J_p V_p^0`). A degenerate or twisted domain is a ValueError on
        every rank (collective)."""
        corners = particles.fields["corners"] + dt * corner_velocity()
        _, _, volume, centroid = domain_geometry(corners, particles.comm)
        particles.fields["corners"], particles.x, particles.volume = corners, centroid, volume


def _ugimp(order: int | None = None) -> GIMP:
    return GIMP(order, deform=False, name="ugimp")


def _cpgimp(order: int | None = None) -> GIMP:
    return GIMP(order, deform=True, name="cpgimp")


#: the domains by name: ``gimp`` (uGIMP unless ``deform=True``), ``ugimp`` (boxes of the
#: initial size) and ``cpgimp`` (boxes stretched by diag F) are exact unless given an ``order``
DOMAINS = {"point": Point, "gimp": GIMP, "ugimp": _ugimp, "cpgimp": _cpgimp, "cpdi1": CPDI1, "cpdi2": CPDI2}
GIMP_NAMES = ("gimp", "ugimp", "cpgimp")


def make_domain(name: str, **kwargs):
    """A particle domain by name.

    Args:
        name: ``point``, ``gimp`` (uGIMP), ``ugimp``, ``cpgimp``, ``cpdi1`` or ``cpdi2``.
        kwargs: The domain's options (e.g. ``order`` of a Gauss-rule GIMP).

    Returns:
        The domain object (:mod:`fempm.transfer.domains`).

    Raises:
        ValueError: An unknown name.
    """
    if name not in DOMAINS:
        raise ValueError(f"unknown option domain={name!r}; expected one of {', '.join(DOMAINS)}")
    return DOMAINS[name](**kwargs)


def step_domain(name: str | Domain, gimp_order: int | None = None, gimp_deform: bool = False) -> Domain:
    """The domain of the step options (:class:`fempm.stepping.StepOptions`): a :class:`Domain`,
    or a name with ``gimp_order`` for the GIMP domains and ``gimp_deform`` for ``gimp``
    (``ugimp`` and ``cpgimp`` fix it)."""
    if isinstance(name, Domain):
        return name
    if name not in GIMP_NAMES:
        return make_domain(name)
    return make_domain(name, order=gimp_order, **({"deform": gimp_deform} if name == "gimp" else {}))
