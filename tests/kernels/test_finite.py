"""The compiled non-finite particle check against its numpy reference."""

import numpy as np
import pytest

from fempm.kernels import finite


@pytest.mark.parametrize("d", [1, 2, 3])
def test_the_nonfinite_particles_are_those_of_the_numpy_reference(d):
    rng = np.random.default_rng(d)
    n = 200
    x, v, sigma = rng.standard_normal((n, d)), rng.standard_normal((n, d)), rng.standard_normal((n, d, d))
    x[3, 0], v[7, d - 1], sigma[11, 0, d - 1] = np.nan, np.inf, -np.inf
    v[13, 0] = 1e200  # finite, but its kinetic energy density is not
    sigma[17, d - 1, 0] = 1e300  # finite: not flagged
    got, ref = finite.nonfinite_numba(x, v, sigma), finite.nonfinite_numpy(x, v, sigma)
    assert got.dtype == np.bool_ and np.array_equal(got, ref)
    assert np.flatnonzero(got).tolist() == [3, 7, 11, 13]
    assert finite.nonfinite_numba(x[:0], v[:0], sigma[:0]).shape == (0,)
