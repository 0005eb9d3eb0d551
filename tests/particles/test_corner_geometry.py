"""The compiled geometry of corner-tracked domains (fempm.kernels.corners) against its numpy
reference (fempm.particles.corners.domain_geometry_numpy): weights, gradient weights, volumes
and centroids to round-off for simplices and boxes in 1, 2 and 3 dimensions, distorted and
mirrored, and the same error for degenerate and twisted domains."""

import fempm  # noqa: F401  (before dolfinx)
import numpy as np
import pytest

from fempm.particles.corners import box_corners, corner_signs, domain_geometry, domain_geometry_numpy


def domains(d: int, simplex: bool, n: int = 50, seed: int = 1):
    rng = np.random.default_rng(seed)
    if simplex:
        ref = np.vstack([np.zeros(d), np.eye(d)])
    else:
        ref = 0.5 * (corner_signs(d) + 1.0)
    A = np.eye(d) + 0.3 * rng.standard_normal((n, d, d))
    corners = np.einsum("nij,cj->nci", A, ref) + rng.standard_normal((n, 1, d))
    return corners + 0.05 * rng.standard_normal(corners.shape)  # distorted, not affine images


@pytest.mark.parametrize("d", [1, 2, 3])
@pytest.mark.parametrize("simplex", [True, False])
def test_compiled_geometry_equals_numpy(d, simplex):
    corners = domains(d, simplex)
    corners[::7] = corners[::7, ::-1]  # some mirrored (negative Jacobian throughout)
    if not simplex or d == 1:
        ok = np.ones(len(corners), dtype=bool)
        for p, c in enumerate(corners):
            try:
                domain_geometry_numpy(c[None])
            except ValueError:
                ok[p] = False
        corners = corners[ok]
    got, ref = domain_geometry(corners), domain_geometry_numpy(corners)
    for a, b in zip(got, ref):
        assert a.shape == b.shape
        assert np.allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max())


def test_box_weights_and_centroids():
    x = np.array([[0.3, 0.4], [1.0, -2.0]])
    w, g, vol, centroid = domain_geometry(box_corners(x, np.array([[0.1, 0.2], [0.5, 0.5]])))
    assert np.allclose(w, 0.25) and np.allclose(vol, [0.08, 1.0]) and np.allclose(centroid, x)
    assert np.allclose(g.sum(axis=1), 0.0, atol=1e-14)


@pytest.mark.parametrize("simplex", [True, False])
def test_degenerate_domains_are_an_error(simplex):
    corners = domains(2, simplex, n=4)
    corners[2] = corners[2, :1]  # every corner at one point
    with pytest.raises(ValueError, match="1 CPDI2 .* degenerate or twisted"):
        domain_geometry(corners)
    with pytest.raises(ValueError, match="1 CPDI2 .* degenerate or twisted"):
        domain_geometry_numpy(corners)


@pytest.mark.parametrize("simplex", [True, False])
def test_closed_form_2d_geometry_of_the_moving_pass(simplex):
    """fempm.kernels.corners.corner_geometry (the closed forms CPDI2's moving pass uses:
    the divergence theorem for g, det J linear for w) equals the numpy reference on distorted
    and mirrored triangles and quadrilaterals, and counts the twisted ones."""
    numba = pytest.importorskip("numba")
    from fempm.kernels.corners import corner_geometry

    @numba.njit
    def geometry(corners, w, g, vol, centroid, twisted):
        for p in range(len(corners)):
            vol[p], centroid[p, 0], centroid[p, 1], twisted[p] = corner_geometry(corners, p, w, g)

    corners = domains(2, simplex, n=200, seed=3)
    corners[::7] = corners[::7, ::-1]  # mirrored
    n, k, _ = corners.shape
    out = np.empty((n, k)), np.empty((n, k, 2)), np.empty(n), np.empty((n, 2))
    twisted = np.zeros(n, dtype=np.bool_)
    geometry(corners, *out, twisted)
    ok = np.ones(n, dtype=bool)
    for p, c in enumerate(corners):
        try:
            domain_geometry_numpy(c[None])
        except ValueError:
            ok[p] = False
    assert np.array_equal(twisted, ~ok) and (simplex or 0 < np.count_nonzero(twisted) < n // 4)
    for a, b in zip(out, domain_geometry_numpy(corners[ok])):
        assert np.allclose(a[ok], b, rtol=1e-12, atol=1e-12 * np.abs(b).max())
