r"""The particles whose state is not finite (:func:`fempm.stepping.checks.nonfinite_particles`),
in one compiled pass: position, stress and kinetic energy density :math:`v_p \cdot v_p`
(hence velocity). ``nonfinite_numpy`` is the reference it is tested against
(``tests/kernels/test_finite.py``)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from fempm.kernels.choice import pick

__all__ = ["nonfinite"]


def _rows(a: npt.NDArray) -> npt.NDArray:
    """``a`` (n, ...) as (n, k) rows (n = 0 included)."""
    return a.reshape(len(a), int(np.prod(a.shape[1:])))


def nonfinite_numpy(x: npt.NDArray, v: npt.NDArray, sigma: npt.NDArray) -> npt.NDArray[np.bool_]:
    speed2 = np.einsum("nd,nd->n", v, v) if len(x) else np.zeros(0)
    return ~(np.isfinite(x).all(1) & np.isfinite(speed2) & np.isfinite(_rows(sigma)).all(1))


try:
    from numba import njit

    @njit(cache=True, error_model="numpy")
    def _nonfinite(x, v, sigma):  # pragma: no cover - compiled
        n = x.shape[0]
        bad = np.zeros(n, dtype=np.bool_)
        for p in range(n):
            s = 0.0  # 0 * inf and inf - inf are NaN: one sum tells whether all its terms are finite
            for i in range(x.shape[1]):
                s += 0.0 * x[p, i]
            speed2 = 0.0
            for i in range(v.shape[1]):
                speed2 += v[p, i] * v[p, i]
            s += 0.0 * speed2
            for i in range(sigma.shape[1]):
                s += 0.0 * sigma[p, i]
            bad[p] = s != 0.0  # (NaN != 0)
        return bad

    def nonfinite_numba(x, v, sigma):
        return _nonfinite(np.ascontiguousarray(x), np.ascontiguousarray(v),
                          _rows(np.ascontiguousarray(sigma)))
except ImportError:  # pragma: no cover - numba is a dependency
    nonfinite_numba = nonfinite_numpy

nonfinite = pick(nonfinite_numba, nonfinite_numpy)
