"""The implicit step's compiled passes (fempm.kernels.implicit) against their numpy references,
to round-off, in 1, 2 and 3 dimensions; and the tangent's pattern kept while the particles keep
their dofs."""

import numpy as np
import pytest

from fempm.kernels import implicit as ki
from fempm.kernels import implicit_blocks as kb


@pytest.fixture(params=[(1, 2), (2, 3), (2, 6), (3, 4), (3, 8)], ids=["interval", "P1-triangle", "P2-triangle",
                                                                     "tetrahedron", "hexahedron"])
def data(request):
    d, k = request.param
    rng = np.random.default_rng(10 * d + k)
    n, nd = 300, 71
    dofs = rng.integers(0, nd, size=(n, k)).astype(np.int32)
    grads = rng.standard_normal((n, k, d))
    values = rng.random((n, k))
    du = 0.05 * rng.standard_normal((nd, d))
    G = 0.1 * rng.standard_normal((n, d, d))
    sigma = rng.standard_normal((n, d, d))
    sigma = sigma + np.swapaxes(sigma, 1, 2)
    D = rng.standard_normal((n, d, d, d, d))
    F = np.eye(d) + 0.1 * rng.standard_normal((n, d, d))
    return dict(d=d, k=k, dofs=dofs, grads=grads, values=values, du=du, G=G, sigma=sigma, D=D, F=F,
                volume=rng.random(n) + 0.5, mass=rng.random(n) + 0.5)


def close(a, b, tol=1e-12):
    assert a.shape == b.shape
    assert np.abs(a - b).max() <= tol * max(1.0, np.abs(b).max())


def test_increment_gradients(data):
    close(ki.increment_gradients_numba(data["du"], data["dofs"], data["grads"]),
          ki.increment_gradients_numpy(data["du"], data["dofs"], data["grads"]))


def test_determinants_and_deformation(data):
    from fempm.materials.tangent import deformed

    close(ki.increment_determinants_numba(data["G"]), ki.increment_determinants_numpy(data["G"]))
    close(deformed(data["F"], data["G"]), data["F"] + data["G"] @ data["F"])


@pytest.mark.parametrize("tangent", [False, True])
def test_nominal_stress_and_tangent(data, tangent):
    D = data["D"] if tangent else None
    P, A, J = ki.nominal_numba(data["sigma"], D, data["G"])
    P0, A0, J0 = ki.nominal_numpy(data["sigma"], D, data["G"])
    close(P, P0)
    close(J, J0)
    assert (A is None) == (A0 is None) == (not tangent)
    if tangent:
        close(A, A0)


def test_an_inverting_increment_gives_its_determinant(data):
    G = data["G"].copy()
    G[0] = -np.eye(data["d"])  # det(I + G) = 0
    P, _, J = ki.nominal_numba(data["sigma"], None, G)
    assert J[0] == 0.0 and np.all(J[1:] > 0)


@pytest.mark.parametrize("factor, consistent", [(0.0, False), (3.5, False), (3.5, True)])
def test_tangent_blocks(data, factor, consistent):
    args = (data["grads"], data["values"], data["D"][:, :, :, :, :], data["volume"], data["mass"], factor, consistent, 11)
    got, ref = kb.tangent_blocks_numba(*args), kb.tangent_blocks_numpy(*args)
    close(got, ref)
    assert len(got) == len(data["dofs"]) * (data["k"] * data["d"]) ** 2 + 11 and not got[-11:].any()
    slot = np.random.default_rng(5).integers(0, 40, len(data["dofs"]))  # blocks summed by group
    got, ref = kb.tangent_blocks_numba(*args, slot, 40), kb.tangent_blocks_numpy(*args, slot, 40)
    close(got, ref)
    m2 = (data["k"] * data["d"]) ** 2
    close(got[:40 * m2].reshape(40, m2).sum(axis=0), kb.tangent_blocks_numpy(*args)[:-11].reshape(-1, m2).sum(axis=0))


@pytest.mark.parametrize("factor, consistent", [(0.0, False), (3.5, False), (3.5, True)])
def test_tangent_blocks_of_groups_sharing_their_gradients(data, factor, consistent):
    """Particles of a group with the same gradients (a cell of degree 1 on affine simplices):
    their summed tangents and masses, then one block, equal the blocks summed particle by particle."""
    rng = np.random.default_rng(9)
    slot = rng.integers(0, 40, len(data["dofs"]))
    slot[:40] = np.arange(40)  # every group holds a particle
    first = np.array([np.flatnonzero(slot == g)[0] for g in range(40)])
    grads = data["grads"][first][slot]  # a group's particles share its gradients
    args = (grads, data["values"], data["D"], data["volume"], data["mass"], factor, consistent, 11)
    got = kb.cell_tangent_blocks_numba(*args, slot, first)
    close(got, kb.tangent_blocks_numpy(*args, slot, 40))
    close(kb.cell_tangent_blocks_numpy(*args, slot, first), got)


def test_linear_elastic_tangent(data):
    close(ki.linear_elastic_tangent_numba(data["F"], 2.0, 0.7), ki.linear_elastic_tangent_numpy(data["F"], 2.0, 0.7))


def test_the_tangent_pattern_is_kept_while_the_particles_keep_their_dofs():
    """Cook's membrane in quasi-static steps (load 1e-4: no particle leaves its triangle): one
    layout of the pattern for every step; a particle with other dofs lays it out again."""
    import dataclasses

    from fempm.scene import run
    from fempm.scenes import cook_membrane
    from fempm.stepping import StepOptions

    scene = cook_membrane(h=4.0, load=1e-4, frames=0)
    scene.options = StepOptions(integrator="implicit", dynamics="quasi-static", load_ramp=scene.t_end)
    scene = dataclasses.replace(scene, dt=scene.t_end / 4)
    solver = run(scene, None, progress=False)["solver"]
    assert solver.step_count == 4 and solver.implicit.pattern.layouts == 1
