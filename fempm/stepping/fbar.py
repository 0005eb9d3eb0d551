r"""F-bar against volumetric locking (``StepOptions(volumetric="fbar")``): the volumetric part of
each particle's deformation increment averaged over a patch of the grid.

Low-order cells lock near incompressibility because each particle's volume change is a
constraint: with P1 triangles there are about as many as displacement dofs. F-bar (de Souza
Neto et al. 1996; Coombs et al. 2018 for MPM) keeps each particle's isochoric increment and
replaces its volume change by a patch average. Here the patch of a particle is the cells around
the nodes of its cell, weighted by the basis: the increments' volume ratios
:math:`\Delta J_p = \det \Delta F_p`, :math:`\Delta F_p = I + \Delta t L_p`, are projected on the
nodes with the volumes :math:`V^n` of the particle's body, and interpolated back,

.. math::
    \Delta J_i = \frac{\sum_q V^n_q N_{iq} \Delta J_q}{\sum_q V^n_q N_{iq}}, \qquad
    \overline{\Delta J}_p = \sum_i N_{ip} \Delta J_i, \qquad
    \overline{\Delta F}_p = \Big(\frac{\overline{\Delta J}_p}{\Delta J_p}\Big)^{1/d} \Delta F_p

(:func:`patch_average`), so that one volumetric constraint remains per node (as the averaged
nodal pressure of Bonet and Burton 1998 for linear tetrahedra). A uniform dilation is left as it
is and the average conserves volume, :math:`\sum_p V^n_p \overline{\Delta J}_p = \sum_p V^n_p
\Delta J_p`. The step then runs with :math:`\bar L = (\overline{\Delta F} - I) / \Delta t`
(:meth:`FBar.rate`): :math:`F \leftarrow \overline{\Delta F} F`, :math:`V = \det F\, V^0`.

The internal force takes the patch-averaged pressure (:meth:`FBar.force_stress`): the average
is self-adjoint in the weights :math:`V^n`, so the force is the derivative of the stored energy
of the averaged increments and a run conserves it. (Averaging the total volume ratio instead
makes the averaged volume change when a particle moves from patch to patch, which the forces do
not see: a near-incompressible body gains energy.) The patches do not cross bodies (one average
per value of ``fields["body"]``). A law says that it takes the averaged deformation with the
class attribute ``volumetric_average = True`` (every law of :mod:`fempm.materials`).

What is averaged is the law's volumetric strain: :math:`\det F` by default; for a small-strain
law whose volumetric strain is :math:`\mathrm{tr}\,F - d` (``volumetric_measure = "trace"``,
:class:`fempm.materials.LinearElastic`) its increment :math:`\Delta\theta = \Delta t\,
\mathrm{tr}(L F^n)`, and :math:`\bar F^{n+1} = \Delta F F^n + \frac1d (\overline{\Delta\theta} -
\Delta\theta) I`: a rotation changes :math:`\mathrm{tr}\,F` and not :math:`\det F`, so averaging
:math:`\det F` for such a law leaves its pressure without the average it is conjugate to, and a
rotating body gains energy (the colliding disks at nu = 0.4999 blow up at the impact).

Point particles on a space of the compiled passes take :class:`fempm.stepping.fbar_grid.FBarPointGrid`,
the same average in compiled passes (:mod:`fempm.kernels.fbar`), tested against :class:`FBar` on
the numpy step; the other options run this module's numpy on that step.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from fempm.transfer.basis import ParticleBasis
from fempm.transfer.mapping import p2g

__all__ = ["VOLUMETRIC", "FBar", "check_laws", "patch_average", "patch_weights", "trace_measure", "volumetric"]

#: the names ``StepOptions(volumetric=...)`` takes
VOLUMETRIC = ("standard", "fbar")


@dataclass(frozen=True)
class FBar:
    """The nodal-patch F-bar average of the deformation increments (see the module)."""

    name = "fbar"

    def rate(self, basis: ParticleBasis, volume: npt.NDArray, body: npt.NDArray, materials: Sequence,
             F: npt.NDArray, L: npt.NDArray, dt: float) -> npt.NDArray:
        r""":math:`\bar L` (n, d, d) of a step with velocity gradients ``L`` of particles of volumes
        ``volume`` (:math:`V^n`), deformation gradients ``F`` (:math:`F^n`) and bodies ``body``
        (indices into ``materials``): :math:`I + \Delta t \bar L = \overline{\Delta F}` (see the
        module); for the bodies of a law whose volumetric strain is :math:`\mathrm{tr}\,F - d`
        (``volumetric_measure = "trace"``, :class:`fempm.materials.LinearElastic`) the average is
        of :math:`\Delta\theta = \Delta t\, \mathrm{tr}(L F^n)` instead, and
        :math:`\bar F^{n+1} = \Delta F F^n + \frac{1}{d}(\overline{\Delta\theta} - \Delta\theta) I`.

        Note:
            Collective (the nodal sums over ranks).
        """
        d = L.shape[1]
        eye = np.eye(d)
        dF = eye + dt * L
        dJ = np.linalg.det(dF)
        by_trace = trace_measure(materials)[body]
        dtheta = dt * np.einsum("pij,pji->p", L, F)
        averaged = patch_average(basis, volume, body, len(materials), np.where(by_trace, dtheta, dJ))
        scale = (np.where(by_trace, 1.0, averaged) / dJ) ** (1.0 / d)
        L_bar = (np.where(by_trace[:, None, None], dF, scale[:, None, None] * dF) - eye) / dt
        if by_trace.any():
            shift = np.where(by_trace, (averaged - dtheta) / d, 0.0)
            L_bar += (shift / dt)[:, None, None] * np.linalg.inv(F)
        return L_bar

    def force_stress(self, basis: ParticleBasis, volume: npt.NDArray, body: npt.NDArray, bodies: int,
                     sigma: npt.NDArray) -> npt.NDArray:
        r"""The stresses whose divergence is the internal force of the averaged kinematics,
        :math:`\sigma_p - p_p I + \bar p_p I` with :math:`p = \mathrm{tr}\,\sigma / d` and
        :math:`\bar p` its patch average (the same weights): the virtual work
        :math:`\sum_p V_p p_p \delta \bar\theta_p` of the averaged volume change equals
        :math:`\sum_q V_q \bar p_q \delta\theta_q`, the operator being self-adjoint in the
        volume weights. (Without it the forces are not the derivative of the stored energy and
        an explicit run gains energy.) Collective."""
        d = sigma.shape[1]
        pressure = np.trace(sigma, axis1=1, axis2=2) / d
        return sigma + (patch_average(basis, volume, body, bodies, pressure) - pressure)[:, None, None] * np.eye(d)


def patch_average(basis: ParticleBasis, volume: npt.NDArray, body: npt.NDArray, bodies: int,
                  values: npt.NDArray) -> npt.NDArray:
    r"""The nodal-patch average of per-particle ``values`` (n,), within each of the ``bodies``
    bodies (``body`` (n,) the particles' indices, the same count on every rank):
    :math:`\bar f_p = \sum_i N_{ip} \sum_q V_q N_{iq} f_q / \sum_q V_q N_{iq}` over the
    particles q of p's body. Collective."""
    weights = patch_weights(volume, body, bodies)
    nodal = p2g(basis, np.hstack([weights, weights * values[:, None]]))
    mass = nodal[:, :bodies]
    averaged = np.where(mass > 0.0, nodal[:, bodies:] / np.where(mass > 0.0, mass, 1.0), 0.0)
    return basis.gather(averaged)[np.arange(len(body)), body]  # (n, bodies): each particle's own body


def patch_weights(volume: npt.NDArray, body: npt.NDArray, bodies: int) -> npt.NDArray:
    """(n, bodies): each particle's volume in its body's column, zero in the others (the
    weights of :func:`patch_average`)."""
    return np.stack([np.where(body == b, volume, 0.0) for b in range(bodies)], axis=1)


def trace_measure(materials: Sequence) -> npt.NDArray[np.bool_]:
    """(bodies,): whether each law's volumetric strain is ``tr F - d`` (``volumetric_measure =
    "trace"``) rather than ``det F``."""
    return np.array([getattr(mat, "volumetric_measure", "J") == "trace" for mat in materials], dtype=bool)


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
