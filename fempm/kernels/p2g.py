r"""Particle-to-grid kernels over the per-particle basis arrays of
:class:`fempm.transfer.basis.ParticleBasis` (dofs, values ``S`` and gradients ``G``, one row
per particle), local sums (the caller adds the ghost contributions to their owners once):

* :func:`nodal_forces`: the internal and external nodal forces in one scatter,

  .. math::
      f_i = \sum_p \Big(-V_p\, \sigma_p \nabla N_i(x_p) + N_i(x_p)\, f^{ext}_p\Big);

* :func:`scatter_weighted`: :math:`\sum_p S_{pa} w_{pc}` into the dofs :math:`d(p, a)`;
* :func:`scatter_gradients`: :math:`\sum_p \sum_b W_{p,rb} G_{p,ab}` (e.g. the mass
  gradients, :math:`W_p = M_p I`).
"""

from __future__ import annotations

import functools

import numpy as np
import numpy.typing as npt

from fempm.kernels.choice import pick

__all__ = ["nodal_forces", "nodal_forces_numpy", "scatter_gradients", "scatter_gradients_numpy", "scatter_weighted",
           "scatter_weighted_numpy"]


#: the widest array of weights the scatter kernels are compiled for (wider ones: a loop read at run time)
CONSTANT_COLUMNS = 3


def _bincount(dofs, contrib, ndofs):
    """Per-particle, per-local-dof contributions (n, K, k) summed into the dofs (ndofs, k)."""
    out = np.empty((ndofs, contrib.shape[2]))
    for c in range(contrib.shape[2]):  # loop over components, not particles
        out[:, c] = np.bincount(dofs.ravel(), weights=contrib[:, :, c].ravel(), minlength=ndofs)
    return out


def nodal_forces_numpy(dofs, S, G, volume, sigma, fext, ndofs):
    contrib = -volume[:, None, None] * np.einsum("nae,nce->nac", G, sigma) + S[:, :, None] * fext[:, None, :]
    return _bincount(dofs, contrib, ndofs)


def scatter_weighted_numpy(dofs, S, w, ndofs):
    return _bincount(dofs, S[:, :, None] * w[:, None, :], ndofs)


def scatter_gradients_numpy(dofs, G, W, ndofs):
    return _bincount(dofs, G @ np.swapaxes(W, 1, 2), ndofs)


try:
    from numba import njit

    @functools.cache
    def _gradients(k: int, c: int, d: int):
        """:func:`scatter_gradients` of ``k`` dofs a particle, ``c`` rows of ``W`` (0: read at run
        time), dimension ``d`` (compile-time loops; :func:`scatter_weighted` is the case d = 1)."""

        @njit(cache=True)
        def gradients(dofs, G, W, out):  # pragma: no cover - compiled
            cw = c if c else W.shape[1]
            for p in range(G.shape[0]):
                for a in range(k):
                    i = dofs[p, a]
                    for r in range(cw):
                        s = 0.0
                        for b in range(d):
                            s += G[p, a, b] * W[p, r, b]
                        out[i, r] += s

        return gradients

    def _width(c: int) -> int:
        """The number of columns a kernel is compiled for: up to :data:`CONSTANT_COLUMNS`, else 0
        (read at run time: fewer variants to compile for the wide arrays of a few callers)."""
        return c if c <= CONSTANT_COLUMNS else 0

    def scatter_weighted_numba(dofs, S, w, ndofs):  # the gradients' scatter of one dimension (views, no copies)
        return scatter_gradients_numba(dofs, np.ascontiguousarray(S)[:, :, None], np.ascontiguousarray(w)[:, :, None],
                                       ndofs)

    def scatter_gradients_numba(dofs, G, W, ndofs):
        out = np.zeros((ndofs, W.shape[1]))
        _gradients(G.shape[1], _width(W.shape[1]), G.shape[2])(np.ascontiguousarray(dofs), np.ascontiguousarray(G),
                                                               np.ascontiguousarray(W), out)
        return out

    @njit(cache=True)
    def _forces(dofs, S, G, volume, sigma, fext, out):  # pragma: no cover - compiled
        n, k = S.shape
        d = sigma.shape[1]
        for p in range(n):
            for a in range(k):
                i = dofs[p, a]
                for c in range(d):
                    s = 0.0
                    for e in range(d):
                        s += sigma[p, c, e] * G[p, a, e]
                    out[i, c] += S[p, a] * fext[p, c] - volume[p] * s

    def nodal_forces_numba(dofs, S, G, volume, sigma, fext, ndofs):
        out = np.zeros((ndofs, sigma.shape[1]))
        _forces(dofs, S, G, volume, np.ascontiguousarray(sigma), np.ascontiguousarray(fext), out)
        return out
except ImportError:  # pragma: no cover
    nodal_forces_numba = nodal_forces_numpy
    scatter_weighted_numba, scatter_gradients_numba = scatter_weighted_numpy, scatter_gradients_numpy


def nodal_forces(dofs: npt.NDArray, S: npt.NDArray, G: npt.NDArray, volume: npt.NDArray, sigma: npt.NDArray,
                 fext: npt.NDArray, ndofs: int) -> npt.NDArray:
    """Local nodal forces (ndofs, d) of the particles' stresses and external forces ``fext``
    (n, d); ghost rows are partial sums."""
    return pick(nodal_forces_numba, nodal_forces_numpy)(dofs, S, G, volume, sigma, fext, ndofs)


def scatter_weighted(dofs: npt.NDArray, S: npt.NDArray, w: npt.NDArray, ndofs: int) -> npt.NDArray:
    """Local sums (ndofs, k) of the values ``S`` (n, K) at the dofs ``dofs`` (n, K) times the
    weights ``w`` (n, k); ghost rows are partial sums."""
    return pick(scatter_weighted_numba, scatter_weighted_numpy)(dofs, S, w, ndofs)


def scatter_gradients(dofs: npt.NDArray, G: npt.NDArray, W: npt.NDArray, ndofs: int) -> npt.NDArray:
    """Local sums (ndofs, k) of the gradients ``G`` (n, K, d) contracted with the tensors ``W``
    (n, k, d), :math:`\\sum_b W_{p,rb} G_{p,ab}`; ghost rows are partial sums."""
    return pick(scatter_gradients_numba, scatter_gradients_numpy)(dofs, G, W, ndofs)
