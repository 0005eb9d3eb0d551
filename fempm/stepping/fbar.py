r"""F-bar against volumetric locking (``StepOptions(volumetric="fbar")``): the volumetric part of
each particle's deformation increment averaged over a patch of the grid.

Low-order cells lock near incompressibility because each particle's volume change is a
constraint: with P1 triangles there are about as many as displacement dofs. F-bar (de Souza
Neto et al. 1996; Coombs et al. 2018 for MPM) keeps each particle's isochoric increment and
replaces its volume change by a patch average. Here the patch of a particle is the cells around
the nodes of its cell, weighted by the basis: the increments' volume ratios
:math:`\Delta J_p = \det \Delta F_p` are projected on the nodes with the volume weights of the
particle's body, and interpolated back,

.. math::
    \Delta J_i = \frac{\sum_p V_p N_{ip} \Delta J_p}{\sum_p V_p N_{ip}}, \qquad
    \overline{\Delta J}_p = \sum_i N_{ip} \Delta J_i, \qquad
    \overline{\Delta F}_p = \Big(\frac{\overline{\Delta J}_p}{\Delta J_p}\Big)^{1/d} \Delta F_p,

so that one volumetric constraint remains per node (as the averaged nodal pressure of Bonet and
Burton 1998 for linear tetrahedra), a uniform dilation is left as it is and the average
conserves volume, :math:`\sum_p V_p \overline{\Delta J}_p = \sum_p V_p \Delta J_p`. The
patches do not cross bodies (one average per value of ``fields["body"]``). A law takes the
averaged :math:`F = \overline{\Delta F} F_n` and, for the rate laws,
:math:`L = (\overline{\Delta F} - I) / \Delta t`; it says it can with the class attribute
``volumetric_average = True`` (every law of :mod:`fempm.materials`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from fempm.transfer.basis import ParticleBasis
from fempm.transfer.mapping import p2g

__all__ = ["VOLUMETRIC", "FBar", "check_laws", "volumetric"]

#: the names ``StepOptions(volumetric=...)`` takes
VOLUMETRIC = ("standard", "fbar")


@dataclass(frozen=True)
class FBar:
    """The nodal-patch F-bar average of the deformation increments (see the module)."""

    name = "fbar"

    def average(self, basis: ParticleBasis, volume: npt.NDArray, body: npt.NDArray,
                dF: npt.NDArray) -> npt.NDArray:
        r""":math:`\overline{\Delta F}_p` (n, d, d) of the increments ``dF`` (n, d, d) of particles
        of volumes ``volume`` (at the step's start) and bodies ``body``.

        Note:
            Collective (the nodal sums over ranks).
        """
        d = dF.shape[1]
        dJ = np.linalg.det(dF)
        bodies = np.unique(body)
        weights = np.stack([np.where(body == b, volume, 0.0) for b in bodies], axis=1)  # one column per body
        nodal = p2g(basis, np.hstack([weights, weights * dJ[:, None]]))
        k = len(bodies)
        mass = nodal[:, :k]
        dJ_nodes = np.where(mass > 0.0, nodal[:, k:] / np.where(mass > 0.0, mass, 1.0), 1.0)
        at_particles = basis.gather(dJ_nodes)  # (n, bodies)
        mine = np.searchsorted(bodies, body)
        dJ_bar = at_particles[np.arange(len(body)), mine]
        return (dJ_bar / dJ)[:, None, None] ** (1.0 / d) * dF


def volumetric(name: str) -> FBar | None:
    """The volumetric treatment named ``name`` (one of :data:`VOLUMETRIC`): None for the standard
    one, :class:`FBar` for ``"fbar"``.

    Raises:
        ValueError: An unknown name.
    """
    if name == "standard":
        return None
    if name == "fbar":
        return FBar()
    raise ValueError(f"unknown option volumetric={name!r}; expected one of {', '.join(VOLUMETRIC)}")


def check_laws(materials: Sequence) -> None:
    """Every law takes F-bar's averaged deformation (``volumetric_average = True``).

    Raises:
        ValueError: A law that does not say so, named.
    """
    for i, mat in enumerate(materials):
        if not getattr(mat, "volumetric_average", False):
            raise ValueError(f"material {i} ({type(mat).__name__}) does not take F-bar's averaged deformation "
                             "(volumetric='fbar'): a law that computes its stress from F or L says so with the class "
                             "attribute volumetric_average = True")
