r"""Particle-to-grid kernels for point particles (one cell per particle).

:func:`nodal_forces`: the internal and external nodal forces in one scatter (local sums; the
caller adds the ghost contributions to their owners once),

.. math::
    f_i = \sum_p \Big(-V_p\, \sigma_p \nabla N_i(x_p) + N_i(x_p)\, f^{ext}_p\Big).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from fempm.kernels.choice import pick

__all__ = ["nodal_forces", "nodal_forces_numpy"]


def nodal_forces_numpy(dofs, S, G, volume, sigma, fext, ndofs):
    contrib = -volume[:, None, None] * np.einsum("nae,nce->nac", G, sigma) + S[:, :, None] * fext[:, None, :]
    out = np.zeros((ndofs, sigma.shape[1]))
    for c in range(sigma.shape[1]):  # loop over components, not particles
        out[:, c] = np.bincount(dofs.ravel(), weights=contrib[:, :, c].ravel(), minlength=ndofs)
    return out


try:
    from numba import njit

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


def nodal_forces(dofs: npt.NDArray, S: npt.NDArray, G: npt.NDArray, volume: npt.NDArray, sigma: npt.NDArray,
                 fext: npt.NDArray, ndofs: int) -> npt.NDArray:
    """Local nodal forces (ndofs, d) of the particles' stresses and external forces ``fext``
    (n, d); ghost rows are partial sums."""
    return pick(nodal_forces_numba, nodal_forces_numpy)(dofs, S, G, volume, sigma, fext, ndofs)
