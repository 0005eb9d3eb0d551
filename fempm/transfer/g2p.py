r"""G2P of a nodal velocity with the step's basis: the PIC/FLIP blend, the grid velocity at the
particles and the velocity gradient,

.. math::
    v_p^{+} = \alpha \big(v_p + \sum_i N_{ip} (v_i^{+} - v_i)\big) + (1 - \alpha) \sum_i N_{ip} v_i^{+},
    \qquad L_p = \sum_i v_i^{+} \otimes \nabla N_{ip}.

Point particles go through the compiled kernels (:mod:`fempm.kernels.g2p`); particle domains
and extended bases through the basis' gathers, the numpy reference.
"""

from __future__ import annotations

import numpy.typing as npt

from fempm import kernels
from fempm.transfer.basis import ParticleBasis

__all__ = ["blend", "velocity_and_gradient", "velocity_gradient"]


def _compiled(basis: ParticleBasis) -> bool:
    return basis.cells is not None and not basis.extended


def velocity_gradient(basis: ParticleBasis, v: npt.NDArray) -> npt.NDArray:
    r""":math:`L_p = \sum_i v_i \otimes \nabla N_{ip}` (n, d, d) of the nodal velocity ``v``."""
    vd, G = v[basis.dofs], basis.gradients  # sum over the particle's dofs a (not over particles)
    return sum(vd[:, a, :, None] * G[:, a, None, :] for a in range(G.shape[1]))


def blend(basis: ParticleBasis, v_new: npt.NDArray, v_old: npt.NDArray, vp: npt.NDArray, flip: float):
    r"""(:math:`v_p^+` with the FLIP blend ``flip`` = :math:`\alpha`, the grid velocity at the
    particles, :math:`L_p`) of the updated and the mapped nodal velocities."""
    if _compiled(basis):
        return kernels.g2p_point(basis.dofs, basis.values, basis.gradients, v_new, v_old, vp, flip)
    vp_grid = basis.gather(v_new)
    blended = flip * (vp + basis.gather(v_new - v_old)) + (1.0 - flip) * vp_grid
    return blended, vp_grid, velocity_gradient(basis, v_new)


def velocity_and_gradient(basis: ParticleBasis, v: npt.NDArray) -> tuple[npt.NDArray, npt.NDArray]:
    """(grid velocity at the particles, :math:`L_p`) of the nodal velocity ``v``."""
    if _compiled(basis):
        return kernels.velocity_and_gradient(basis.dofs, basis.values, basis.gradients, v)
    return basis.gather(v), velocity_gradient(basis, v)
