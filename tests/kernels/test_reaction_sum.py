"""The compiled reaction sum (fempm.kernels.reactions) against its numpy reference,
fempm.stepping.reactions.nodal_reaction: held rows and every row, columns of a kept nodal
array (strided views, as the grids hand them), damping where the nodes move."""

import numpy as np
import pytest

from fempm.kernels.reactions import reaction_sum
from fempm.stepping.reactions import nodal_reaction


@pytest.mark.parametrize("d", [2, 3])
def test_the_compiled_reaction_sum_equals_the_numpy_residual_sum(d):
    rng = np.random.default_rng(d)
    dofs = 57
    nodal = rng.standard_normal((dofs, 1 + 2 * d))  # [m | m v | f], as the point grid keeps them
    mass = np.abs(nodal[:, 0])
    momentum, force = nodal[:, 1:1 + d], nodal[:, 1 + d:]
    v_old, v_new = rng.standard_normal((dofs, d)), rng.standard_normal((dofs, d))
    moving = mass > 0.4
    for rows in (np.arange(40), np.array([3, 9, 10, 33, 56])):
        for flip, damping in ((1.0, 0.0), (0.9, 0.5), (0.0, 2.0)):
            fields = (mass, momentum, force, v_old, v_new, moving)
            ref = nodal_reaction(*fields, 0.01, flip, damping, rows)
            out = np.full(d, np.nan)
            reaction_sum(fields, 0.01, flip, damping, rows, out)
            np.testing.assert_allclose(out, ref, rtol=1e-13, atol=1e-13 * np.abs(ref).max())
