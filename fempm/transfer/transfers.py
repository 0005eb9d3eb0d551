r"""Velocity transfers: what the particles carry to the grid and back, parsed once from the
``transfer`` option into an object (:func:`velocity_transfer`).

With :math:`S_{ip} = \langle N_i \rangle_p` (the basis at a point particle, or its average over
a particle domain), the grid velocity :math:`v_i` mapped from the particles and :math:`v_i^+`
after the grid update, the transfers are:

* :class:`FLIP` (``flip``, blend :math:`\alpha`) and :class:`PIC` (``pic``, :math:`\alpha = 0`):
  P2G :math:`p_i = \sum_p M_p S_{ip} v_p`; G2P
  :math:`v_p^+ = \alpha (v_p + \sum_i S_{ip}(v_i^+ - v_i)) + (1 - \alpha) \sum_i S_{ip} v_i^+`.
* :class:`APIC` (Jiang et al. 2015): each particle carries an affine velocity
  :math:`v_p + C_p (x - x_p)`. G2P: :math:`v_p^+ = \sum_i S_{ip} v_i^+`,
  :math:`B_p = \sum_i S_{ip} v_i^+ (x_i - x_p)^T`, :math:`C_p = B_p D_p^{-1}` with the
  inertia-like :math:`D_p = \sum_i S_{ip} (x_i - x_p)(x_i - x_p)^T` of any finite element basis
  (on degree-1 point particles of affine cells :math:`C_p = L_p`, since
  :math:`(x_j - x_p) \cdot \nabla N_i = \delta_{ij} - N_{ip}` gives
  :math:`S_{ip} (x_i - x_p) = D_p \nabla N_{ip}`; no inverse, and none of :math:`D_p`'s
  singularity on a cell's edges), and the spin :math:`s_p = \epsilon : B_p^T`. P2G:
  :math:`p_i = \sum_p M_p S_{ip} (v_p + \hat C_p (x_i - x_p))` with
  :math:`\hat C_p = C_p + W(\omega_p)`, the rotation :math:`W(\omega_p)` that gives the carried
  field the stored spin at the particle's present :math:`D_p`,
  :math:`\epsilon : (\hat C_p D_p)^T = s_p` (:func:`fempm.transfer.affine.carried_matrix`).
  The fields ``affine`` and ``affine_spin`` hold :math:`C_p` and :math:`s_p`; the particles'
  angular momentum is :math:`\sum_p M_p (x_p \times v_p + s_p)`, which the lumped map keeps to
  round-off (:func:`fempm.transfer.affine.angular_momentum`). Jiang et al. keep :math:`B_p`
  and map :math:`B_p D_p^{-1}` at the new position, which conserves the same; on a degree-1
  basis that is :math:`M_p B_p \nabla N_{ip}`, momentum on nodes whose mass :math:`M_p N_{ip}`
  vanishes as :math:`D_p` changes under the motion (on B-splines of degree 2 and more
  :math:`D_p` is constant), while :math:`\hat C_p` moves momentum in proportion to
  :math:`N_{ip}`.
* :class:`TPIC` (Nakamura et al. 2023): the particle carries its velocity gradient,
  :math:`C_p = \sum_i v_i \otimes \nabla S_{ip}` (the :math:`L_p` of G2P), in ``affine``;
  P2G :math:`p_i = \sum_p M_p S_{ip} (v_p + C_p (x_i - x_p))`; G2P as APIC's velocity.
* :class:`XPIC` (``xpic``, order m; Hammerquist and Nairn 2017): the particles' velocities are
  first extrapolated on the grid by the series FMPM(m) sums,
  :math:`v^{*} = \sum_{r=0}^{m-1} (I - m_L^{-1} M_C)^r\, m_L^{-1} p`, then
  :math:`v_p^+ = \sum_i S_{ip} (v^{*}_i + v_i^+ - v_i)`: XPIC(1) is PIC, and with the lumped
  mass XPIC(m) is FMPM(m) with lumped forces and PIC; the particles move, and their strain
  rate is taken, with :math:`v^+` as under the other transfers.

Which grid velocity the momenta give depends on the mass model, with one formula for the
affine transfers, :math:`a_i = \sum_p M_p S_{ip} C_p (x_i - x_p)` the affine part of P2G:

.. math::
    v = M_k^{-1} p + (I - m_L^{-1} M_C)^{k-1} m_L^{-1} a

(:math:`M_k^{-1}` the FMPM(k) series of :mod:`fempm.transfer.fmpm`): the lumped mass (k = 1)
solves :math:`m_L v = p + a`, FMPM(k) starts its Richardson steps from that solve and
corrects it with the residual of :math:`p`, and the consistent mass (:math:`k \to \infty`)
solves :math:`M_C v = p`: with point quadrature the Galerkin projection of the particle's
affine field, :math:`\sum_p M_p S_{ip} (v_p + C_p (x - x_p))|_{x = x_p}`, is its value, so the
affine part drops out of the exact projection, which reproduces affine fields and keeps the
angular momentum :math:`\sum_p M_p x_p \times v_p` by itself. Each form maps an affine velocity
field exactly (P2G then G2P returns it) for every mass model.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from typing import ClassVar

from fempm.transfer.mass_models import MAX_ORDER

__all__ = ["AFFINE_FIELD", "APIC", "FLIP", "PIC", "SPIN_FIELD", "TPIC", "TRANSFERS", "XPIC", "Transfer", "velocity_transfer"]

#: the particle field that holds the affine velocity matrix C_p (APIC, TPIC), (n, d, d)
AFFINE_FIELD = "affine"
#: the particle field that holds APIC's spin s_p, (n, 1) in 2D, (n, 3) in 3D
SPIN_FIELD = "affine_spin"


@dataclass(frozen=True)
class Transfer:
    """A velocity transfer (see the module).

    Attributes:
        name: the option's name.
        kind: the compiled kernels' code of the affine matrix (0: none, 1: APIC's B, 2: TPIC's C).
        blend: the FLIP fraction of the particle update (0: the grid velocity alone).
        order: XPIC's m (1 for the others: no extrapolation).
    """

    name: ClassVar[str] = ""
    kind: ClassVar[int] = 0
    blend: float = 0.0
    order: int = 1

    @property
    def affine(self) -> bool:
        """Whether the particles carry an affine matrix (the field :data:`AFFINE_FIELD`)."""
        return self.kind > 0

    @property
    def extrapolates(self) -> bool:
        """Whether the particle update extrapolates the grid velocity first (XPIC(m), m > 1)."""
        return self.order > 1

    @property
    def label(self) -> str:
        """The transfer's name in tables and messages."""
        return self.name.upper()


@dataclass(frozen=True)
class FLIP(Transfer):
    name: ClassVar[str] = "flip"
    blend: float = 1.0

    @property
    def label(self) -> str:
        return "FLIP" if self.blend == 1.0 else f"FLIP({self.blend:g})"


@dataclass(frozen=True)
class PIC(Transfer):
    name: ClassVar[str] = "pic"


@dataclass(frozen=True)
class APIC(Transfer):
    name: ClassVar[str] = "apic"
    kind: ClassVar[int] = 1


@dataclass(frozen=True)
class TPIC(Transfer):
    name: ClassVar[str] = "tpic"
    kind: ClassVar[int] = 2


@dataclass(frozen=True)
class XPIC(Transfer):
    name: ClassVar[str] = "xpic"
    order: int = 2

    @property
    def label(self) -> str:
        return f"XPIC({self.order})"


#: the transfers by option name
TRANSFERS = {t.name: t for t in (FLIP, PIC, APIC, TPIC, XPIC)}


def velocity_transfer(name: str | Transfer, flip: float = 1.0, xpic_order: int = 2) -> Transfer:
    """The transfer of the options ``transfer``, ``flip`` (the blend of ``flip``) and
    ``xpic_order`` (the m of ``xpic``).

    Raises:
        ValueError: An unknown name, or an XPIC order that is not an integer in [1, 10].
    """
    if isinstance(name, Transfer):
        return name
    if name not in TRANSFERS:
        raise ValueError(f"unknown option transfer={name!r}; expected one of {', '.join(TRANSFERS)}")
    if isinstance(xpic_order, bool) or not isinstance(xpic_order, numbers.Integral) or not 1 <= xpic_order <= MAX_ORDER:
        raise ValueError(f"xpic_order={xpic_order!r} must be an integer in [1, {MAX_ORDER}] (XPIC(1) is PIC)")
    if name == "flip":
        return FLIP(float(flip))
    if name == "xpic":
        return XPIC(order=int(xpic_order))
    return TRANSFERS[name]()
