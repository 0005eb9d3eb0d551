"""A law's tangent kept for a step where it does not depend on the increment
(fempm.materials.tangent.tangent_fixed_in_step)."""

import numpy as np

from fempm.materials import LinearElastic, NeoHookean
from fempm.materials.tangent import tangent_fixed_in_step


class CurvedElastic(LinearElastic):
    """A subclass whose own tangent depends on the increment: it does not inherit the flag."""

    def tangent(self, F, G, sigma=None, state=None):
        return (1.0 + np.abs(G).sum()) * super().tangent(F, G, sigma, state)


def test_only_a_law_linear_in_F_keeps_its_tangent_for_the_step():
    assert tangent_fixed_in_step(LinearElastic(1.0, 0.3))
    assert not tangent_fixed_in_step(NeoHookean(1.0, 0.3))
    assert not tangent_fixed_in_step(CurvedElastic(1.0, 0.3))
