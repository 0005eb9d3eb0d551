r"""F-bar in the implicit step: the increment operator with each particle's volume change
averaged over its nodal patch (:mod:`fempm.stepping.fbar`), and its exact tangent.

Each particle's increment :math:`G_p` has a volumetric strain :math:`\theta_p(G_p)`, the law's
own (:attr:`volumetric_measure`): :math:`\det(I + G_p)` by default, :math:`\mathrm{tr}(G_p F^n_p)`
for a law whose volumetric strain is :math:`\mathrm{tr}\,F - d`. Its patch average
:math:`\bar\theta = W \theta` (:func:`fempm.stepping.fbar.patch_average`, weights :math:`V^n`)
replaces it in the increment the law sees,

.. math::
    \bar G_p = \Big(\frac{\bar\theta_p}{\theta_p}\Big)^{1/d} (I + G_p) - I \quad (\det), \qquad
    \bar G_p = G_p + \frac{\bar\theta_p - \theta_p}{d} (F^n_p)^{-1} \quad (\mathrm{tr}),

which is what the explicit F-bar step does with :math:`\Delta t L_p = G_p`. The internal force
is the derivative of the virtual work :math:`\sum_p V^n_p \bar P_p : \delta \bar G_p` with
:math:`\bar P = P(\bar G)` (:func:`fempm.implicit.nominal.nominal_stress`). As the average is
self-adjoint in the weights (:math:`V^n_p W_{pq} = V^n_q W_{qp}`),

.. math::
    f_a = \sum_p V^n_p \big( A_p + \bar\pi_p\, \theta'_p \big) \nabla N_a(x_p), \qquad
    A = \bar P : \frac{\partial \bar G}{\partial G}, \quad
    \pi = \bar P : \frac{\partial \bar G}{\partial \bar\theta}, \quad \bar\pi = W \pi,

(for :math:`\det`: :math:`A = \bar J (\bar\sigma - \bar p I)\Delta F^{-T}` and :math:`\pi = \bar p`).
Its tangent has the particles' own blocks
:math:`\partial A/\partial G + \bar\pi\, \theta''` and a coupling over the patches, through the
nodal averages :math:`D = \mathrm{diag}(1 / \sum_q V^n_q N_{iq})` (one per node and body):

.. math::
    K^{patch} = S^T D T + T^T D U + T^T D\, M_c\, D T,

with :math:`T, S, U` (nodes :math:`\times` dofs) the scatters :math:`\sum_q N_{iq} V^n_q X_q
\nabla N_{aq}` of :math:`X = \theta'`, :math:`\partial A / \partial\bar\theta` and
:math:`\partial\pi / \partial G`, and :math:`M_c = \sum_q V^n_q\, \partial\pi_q/\partial\bar\theta_q\,
N_{iq} N_{jq}` (PETSc products: :class:`PatchCoupling`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
from petsc4py import PETSc

from fempm import petsc as fpetsc
from fempm.implicit.operator import IncrementOperator
from fempm.particles.particle_set import Particles
from fempm.stepping.fbar import patch_average, patch_weights, trace_measure
from fempm.transfer.basis import ParticleBasis

__all__ = ["FBarIncrementOperator", "PatchCoupling", "averaged_stress", "increment_measure", "modified"]


def increment_measure(G, Fn, trace):
    r""":math:`\theta` (n,), :math:`\theta'` (n, d, d) and :math:`\theta''` (n, d, d, d, d) of the
    increments ``G``: :math:`\det(I + G)`, or :math:`\mathrm{tr}(G F^n)` where ``trace`` (bool, n)
    holds (``Fn`` the steps' start deformations)."""
    n, d = G.shape[0], G.shape[1]
    theta, d1, d2 = np.empty(n), np.empty((n, d, d)), np.zeros((n, d, d, d, d))
    j = ~trace
    dF = np.eye(d) + G[j]
    det, inv = np.linalg.det(dF), np.linalg.inv(dF)
    theta[j] = det
    d1[j] = det[:, None, None] * np.swapaxes(inv, 1, 2)
    d2[j] = det[:, None, None, None, None] * (np.einsum("pji,plk->pklij", inv, inv)
                                              - np.einsum("pli,pjk->pklij", inv, inv))
    theta[trace] = np.einsum("pkl,plk->p", G[trace], Fn[trace])
    d1[trace] = np.swapaxes(Fn[trace], 1, 2)
    return theta, d1, d2


def modified(G, theta, theta_bar, Fn, trace):
    r""":math:`\bar G` (n, d, d) of the increments ``G`` of volumetric strains ``theta`` with the
    averages ``theta_bar`` (see the module; NaN where a det average is not positive)."""
    d = G.shape[1]
    eye = np.eye(d)
    with np.errstate(invalid="ignore", divide="ignore"):  # theta_bar <= 0: NaN, which the caller refuses
        scale = np.where(trace, 1.0, theta_bar / np.where(trace, 1.0, theta)) ** (1.0 / d)
    Gbar = scale[:, None, None] * (eye + G) - eye
    if trace.any():
        Gbar[trace] = G[trace] + ((theta_bar - theta)[trace] / d)[:, None, None] * np.linalg.inv(Fn[trace])
    return Gbar


def averaged_stress(G, theta_bar, Fn, trace, P, AA=None):
    r""":math:`A = \bar P : \partial\bar G/\partial G` (n, d, d) and
    :math:`\pi = \bar P : \partial\bar G/\partial\bar\theta` (n,) of the increments ``G`` with
    averaged volumetric strains ``theta_bar``, steps' start deformations ``Fn``, the laws'
    measures ``trace`` (bool, n) and :math:`\bar P` = ``P``; with :math:`\partial\bar P /
    \partial\bar G` = ``AA`` also their derivatives :math:`\partial A/\partial G` (n, d, d, d, d),
    :math:`\partial A/\partial\bar\theta` (n, d, d), :math:`\partial\pi/\partial G` (n, d, d),
    :math:`\partial\pi/\partial\bar\theta` (n,) (else None)."""
    n, d = G.shape[0], G.shape[1]
    eye = np.eye(d)
    H, h = np.empty((n, d, d, d, d)), np.empty((n, d, d))
    extra = [np.zeros((n, d, d, d, d)), np.zeros((n, d, d)), np.zeros((n, d, d)), np.zeros(n)]
    j, t = ~trace, trace
    if j.any():  # Gbar = s (I + G) - I, s = (theta_bar / det)^(1/d)
        F = eye + G[j]
        inv = np.linalg.inv(F)
        tb = theta_bar[j]
        s = (tb / np.linalg.det(F)) ** (1.0 / d)
        sG = -(s / d)[:, None, None] * np.swapaxes(inv, 1, 2)  # ds/dG
        st = s / (d * tb)  # ds/dtheta_bar
        H[j] = s[:, None, None, None, None] * np.einsum("mk,nl->mnkl", eye, eye) + F[:, :, :, None, None] * sG[
            :, None, None]
        h[j] = st[:, None, None] * F
        Pj = P[j]
        q = np.einsum("pmn,pmn->p", Pj, F)
        sGG = -(1.0 / d) * (np.einsum("pij,plk->pklij", sG, inv)
                            - s[:, None, None, None, None] * np.einsum("pli,pjk->pklij", inv, inv))
        extra[0][j] = (np.einsum("pij,pkl->pklij", sG, Pj) + np.einsum("pij,pkl->pklij", Pj, sG)
                       + q[:, None, None, None, None] * sGG)
        extra[1][j] = st[:, None, None] * Pj - (q * st / d)[:, None, None] * np.swapaxes(inv, 1, 2)
        extra[2][j] = st[:, None, None] * Pj + (q / (d * tb))[:, None, None] * sG
        extra[3][j] = q * s * (1.0 - d) / (d * d * tb * tb)
    if t.any():  # Gbar = G + (theta_bar - tr(G Fn)) / d Fn^-1: linear
        Finv = np.linalg.inv(Fn[t])
        H[t] = np.einsum("mk,nl->mnkl", eye, eye) - np.einsum("pmn,plk->pmnkl", Finv, Fn[t]) / d
        h[t] = Finv / d
    A = np.einsum("pmn,pmnkl->pkl", P, H)
    pi = np.einsum("pmn,pmn->p", P, h)
    if AA is None:
        return A, pi, None
    AH = np.einsum("pmnrs,prsij->pmnij", AA, H)
    Ah = np.einsum("pmnrs,prs->pmn", AA, h)
    derivatives = (np.einsum("pmnkl,pmnij->pklij", H, AH) + extra[0],
                   np.einsum("pmnkl,pmn->pkl", H, Ah) + extra[1],
                   np.einsum("pmn,pmnij->pij", h, AH) + extra[2],
                   np.einsum("pmn,pmn->p", h, Ah) + extra[3])
    return A, pi, derivatives


class FBarIncrementOperator(IncrementOperator):
    """The increment operator with F-bar (see the module): the laws see :math:`\\bar G`, the force
    is the average's virtual work, the tangent its exact derivative (the particles' blocks and
    :class:`PatchCoupling`).

    Args:
        basis, particles, materials, finite_difference: as :class:`IncrementOperator`.
    """

    def __init__(self, basis: ParticleBasis, particles: Particles, materials: Sequence,
                 finite_difference: bool = False, dt: float = 1.0):
        super().__init__(basis, particles, materials, finite_difference, dt)
        self.body = particles.fields["body"]
        self.bodies = len(materials)
        self.trace = trace_measure(materials)[self.body]
        self._kin: tuple | None = None  # (G, theta, theta', theta'', theta_bar, Gbar) of the last call

    def average(self, values: npt.NDArray) -> npt.NDArray:
        """The patch average of per-particle ``values`` (collective)."""
        return patch_average(self.basis, self.volume, self.body, self.bodies, values)

    def kinematics(self, G: npt.NDArray) -> tuple:
        r"""(theta, theta', theta'', theta_bar, :math:`\bar G`) of the increments ``G`` (collective)."""
        if self._kin is None or not np.array_equal(self._kin[0], G):
            theta, d1, d2 = increment_measure(G, self.F, self.trace)
            theta_bar = self.average(theta)
            self._kin = (G, theta, d1, d2, theta_bar, modified(G, theta, theta_bar, self.F, self.trace))
        return self._kin[1:]

    def law_gradients(self, G: npt.NDArray) -> npt.NDArray:
        return self.kinematics(G)[-1]

    def forces(self, G: npt.NDArray) -> npt.NDArray:
        _, d1, _, theta_bar, Gbar = self.kinematics(G)
        P, _ = self.stresses(Gbar, tangent=False)
        A, pi, _ = averaged_stress(G, theta_bar, self.F, self.trace, P)
        return A + self.average(pi)[:, None, None] * d1

    def tangents(self, G: npt.NDArray) -> tuple[npt.NDArray, tuple]:
        """The particles' blocks (n, d, d, d, d) and the per-particle factors of the patch
        coupling (theta', dA/dtheta_bar, dpi/dG, dpi/dtheta_bar) (collective)."""
        _, d1, d2, theta_bar, Gbar = self.kinematics(G)
        P, AA = self.stresses(Gbar, tangent=True)
        _, pi, (dA, dAt, dpG, dpt) = averaged_stress(G, theta_bar, self.F, self.trace, P, AA)
        return dA + self.average(pi)[:, None, None, None, None] * d2, (d1, dAt, dpG, dpt)


class PatchCoupling:
    """The tangent's coupling over the patches, :math:`S^T D T + T^T D U + T^T D M_c D T`
    (see the module), assembled as PETSc matrices on the step's basis.

    Args:
        op: The F-bar increment operator of the step.

    Note:
        Collective.
    """

    def __init__(self, op: FBarIncrementOperator):
        b = op.basis
        self.op = op
        self.d, self.B = op.d, op.bodies
        n, k = b.dofs.shape
        nodes = b.dofs * self.B + op.body[:, None]  # (n, k): each particle's nodal rows of its body
        dofs = (b.dofs[:, :, None] * self.d + np.arange(self.d)).reshape(n, -1)  # (n, k d)
        imap = b.index_map
        self.rect = (np.broadcast_to(nodes[:, :, None], (n, k, k * self.d)).ravel(),
                     np.broadcast_to(dofs[:, None, :], (n, k, k * self.d)).ravel())
        self.square = (np.broadcast_to(nodes[:, :, None], (n, k, k)).ravel(),
                       np.broadcast_to(nodes[:, None, :], (n, k, k)).ravel())
        self.T, self.S, self.U = (fpetsc.coo_pattern(imap, *self.rect, bs=self.B, col_bs=self.d) for _ in range(3))
        self.Mc = fpetsc.coo_pattern(imap, *self.square, bs=self.B)
        mass = op.nodal(patch_weights(op.volume, op.body, self.B))
        scale = np.where(mass > 0.0, 1.0 / np.where(mass > 0.0, mass, 1.0), 0.0).ravel()
        self.D = self.T.createVecLeft()
        self.D.array[:] = scale[: imap.size_local * self.B]
        self.scaled: list[PETSc.Mat] | None = None  # D T and D U
        self._products: list[PETSc.Mat] | None = None

    def _scatter(self, X: npt.NDArray) -> npt.NDArray:
        b, op = self.op.basis, self.op
        XN = np.einsum("pkm,pam->pak", X, b.gradients)  # (n, k, d)
        return ((op.volume[:, None] * b.values)[:, :, None, None] * XN[:, None, :, :]).ravel()

    def products(self, factors: tuple) -> list[PETSc.Mat]:
        """The coupling's three terms :math:`S^T D T`, :math:`T^T D U`, :math:`T^T D M_c D T`
        (dofs x dofs, owned rows) of the factors of :meth:`FBarIncrementOperator.tangents`; the
        same Mats, refilled, on later calls (owned here: add them, do not destroy them)."""
        d1, dAt, dpG, dpt = factors
        b, op = self.op.basis, self.op
        for M, X in ((self.T, d1), (self.S, dAt), (self.U, dpG)):
            M.setValuesCOO(self._scatter(X), addv=PETSc.InsertMode.INSERT_VALUES)
            M.assemble()
        mc = (op.volume * dpt)[:, None, None] * b.values[:, :, None] * b.values[:, None, :]
        self.Mc.setValuesCOO(mc.ravel(), addv=PETSc.InsertMode.INSERT_VALUES)
        self.Mc.assemble()
        if self.scaled is None:
            self.scaled = [self.T.copy(), self.U.copy()]
        else:  # the same Mats, so that the products are reused
            self.T.copy(self.scaled[0], structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
            self.U.copy(self.scaled[1], structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        DT, DU = self.scaled
        DT.diagonalScale(L=self.D)
        DU.diagonalScale(L=self.D)
        if self._products is None:
            self._products = [self.S.transposeMatMult(DT), self.T.transposeMatMult(DU), self.Mc.PtAP(DT)]
        else:
            self.S.transposeMatMult(DT, result=self._products[0])
            self.T.transposeMatMult(DU, result=self._products[1])
            self.Mc.PtAP(DT, result=self._products[2])
        return self._products

    def destroy(self) -> None:
        for M in (self.T, self.S, self.U, self.Mc, self.D, *(self.scaled or []), *(self._products or [])):
            M.destroy()
