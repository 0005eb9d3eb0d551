r"""Per-particle pieces shared by the compiled particle passes (:mod:`fempm.kernels.lumped`,
:mod:`fempm.kernels.planar`): the codes of the compiled laws, the stable-time update and the
checks of J."""

from __future__ import annotations

import numpy as np

from fempm.kernels.choice import INLINE
from fempm.kernels.shape import AVAILABLE

#: the codes of the laws the passes evaluate themselves (0: the law's own ``stress``)
NEO_HOOKEAN, LINEAR_ELASTIC = 1, 2

if AVAILABLE:
    from numba import njit

    @njit(inline=INLINE)
    def stable_time(best, bound, m, V, speed, mod, c, p, hp):  # pragma: no cover - compiled
        """``best`` updated with particle ``p`` (mass ``m``, volume ``V``, squared speed ``speed``,
        P-wave modulus ``mod`` of its body, else wave speed ``c[p]``, cell size ``hp``): the
        minimum of :math:`h / (c + |v|)`, or with ``bound`` the maximum of
        :math:`(c^2 + |v|^2) / h^2` (see :func:`_scatter_kernel`). NaN propagates; a particle at
        rest without a wave speed sets no limit."""
        if bound:
            if mod > 0.0:
                r = (mod * V + m * speed) / (m * hp * hp)
            else:
                r = (c[p] * c[p] + speed) / (hp * hp)
            return r if not r <= best else best
        wave = np.sqrt(mod / (m / V)) if mod > 0.0 else c[p]
        total = wave + np.sqrt(speed)
        t = hp / total if not total <= 0.0 else np.inf
        return t if not t >= best else best

    @njit(inline=INLINE)
    def count_j(J, nonfinite_j, inverted, jmin, jmax):  # pragma: no cover - compiled
        """(J finite and positive, then the counts of non-finite and non-positive J and the range
        of the finite J, updated with ``J``)."""
        if not np.isfinite(J):
            return False, nonfinite_j + 1, inverted, jmin, jmax
        jmin, jmax = min(jmin, J), max(jmax, J)
        if J <= 0.0:
            return False, nonfinite_j, inverted + 1, jmin, jmax
        return True, nonfinite_j, inverted, jmin, jmax
