r"""The nominal stress of an increment with respect to the step's start, and its tangent.

The particles sit where the step began (:math:`x_n`), so the basis gradients
:math:`\nabla N_a(x_p)` at them stay fixed while Newton iterates on the displacement increment.
Written on that configuration, the internal force and its derivative are

.. math::
    f_{a i} = \sum_p V_p^n\, P_{im}\, \partial_m N_a, \qquad
    \frac{\partial f_{a i}}{\partial \Delta u_{b k}} = \sum_p V_p^n \partial_m N_a \mathbb{A}_{imkl} \partial_l N_b,

with :math:`V_p^n` the particle's volume at the step's start and the nominal stress
:math:`P = J_\Delta\, \sigma\, \Delta F^{-T}` (:math:`\Delta F = I + G`,
:math:`J_\Delta = \det \Delta F`). Its derivative with respect to :math:`G`, from the law's
:math:`\mathbb{D} = \partial \sigma / \partial G`,

.. math::
    \mathbb{A}_{imkl} = J_\Delta \big( \tilde P_{im} \Delta F^{-1}_{lk}
        + \mathbb{D}_{ijkl}\, \Delta F^{-1}_{mj} - \tilde P_{il}\, \Delta F^{-1}_{mk} \big),
    \qquad \tilde P = \sigma \Delta F^{-T},

holds the material and the geometric stiffness (the first and last terms are the change of
the current volume and of the current basis gradients with the increment).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from fempm.kernels.implicit import nominal

__all__ = ["nominal_stress"]


def nominal_stress(sigma: npt.NDArray, D: npt.NDArray | None, G: npt.NDArray) -> tuple[npt.NDArray, npt.NDArray | None]:
    r"""The nominal stress :math:`P` (n, d, d) and its tangent :math:`\mathbb{A} = \partial P / \partial G`
    (n, d, d, d, d) of particles with Cauchy stress ``sigma`` (n, d, d) after the increment of
    displacement gradient ``G`` (n, d, d), of law tangent ``D`` (n, d, d, d, d) (see the module;
    ``D`` None: :math:`P` alone, the tangent None). One compiled pass
    (:func:`fempm.kernels.implicit.nominal`, its numpy reference ``nominal_numpy``).

    Raises:
        ValueError: An increment that inverts a particle (:math:`\det(I + G) \le 0`).
    """
    P, A, J = nominal(sigma, D, G)
    if np.any(~(J > 0.0)):
        raise ValueError(f"an increment inverts {int(np.count_nonzero(~(J > 0.0)))} particle(s): det(I + G) <= 0")
    return P, A
