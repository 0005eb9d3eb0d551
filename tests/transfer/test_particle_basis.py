"""Implied particle basis functions (docs/particle_basis.md): the properties that hold
exactly, the ones that do not, and the PETSc projection against the dense formula."""

import numpy as np
import pytest

from fempm.transfer.particle_basis import particle_basis_functions
from fempm.studies.particle_basis import DOMAINS, _integrals, _interior_dofs, _interior_particles, line_body, tri_body

OFFSET = np.array([0.13, 0.07])


def line(domain, **kw):
    return line_body(2, DOMAINS[domain], length=16.0, offset=OFFSET[:1], **kw)


@pytest.mark.parametrize("domain", sorted(DOMAINS))
def test_lumped_partition_of_unity_positivity_and_compact_support(domain):
    b = line(domain)
    P = b.psi("lumped")
    touched = np.abs(b.S).sum(axis=0) > 0
    assert np.abs(P.sum(axis=1) - 1)[touched].max() < 1e-14
    assert P.min() >= 0.0 and P.max() <= 1.0 + 1e-15
    k = _interior_particles(b, 1.5)[3]
    assert np.count_nonzero(P[:, k]) <= 4  # the nodes of the (one or two) cells its domain touches


def test_consistent_reproduces_linear_data_but_is_not_positive_nor_compact():
    b = line("cpdi1")
    P = b.psi("consistent")
    touched = np.abs(b.S).sum(axis=0) > 0
    assert np.abs(P @ b.x[:, 0] - b.xd[:, 0])[touched].max() < 1e-12  # up to the body's edge
    k = _interior_particles(b, 1.5)[3]
    assert P[:, k].min() < -0.1  # measured -0.47 (point) to -34 (CPDI, edge dofs)
    assert np.count_nonzero(np.abs(P[touched, k]) > 1e-10) == np.count_nonzero(touched)


def test_lumped_linear_completeness_inside_uniform_1d_bodies_only():
    b = line("point")
    P = b.psi("lumped")
    lc = np.abs(P @ b.x - b.xd)
    inner = np.intersect1d(_interior_dofs(b, 1.5), np.flatnonzero(np.abs(b.S).sum(axis=0) > 0))
    assert lc[inner].max() < 1e-13 and lc.max() > 0.3  # exact inside, 0.46 at the edge
    t = tri_body(DOMAINS["point"], length=10.0, offset=OFFSET)
    lt = np.abs(t.psi("lumped") @ t.x - t.xd)[_interior_dofs(t, 1.5)]
    assert lt.max() > 1e-3  # unstructured triangles: 0.035 even inside


def test_integral_of_lumped_point_basis_is_invariant_in_1d():
    """(xii): the integral of Phi_p stays V_p under translation where the particles' point
    quadrature integrates every N_i exactly (1D, uniform spacing h / 2); averaged domains with
    a Gauss rule (GIMP) or corner interpolation (CPDI) drift by 0.2 % / 0.8 % of V_p."""
    drift = {}
    for domain in ("point", "cpdi1"):
        ints = []
        for t in np.linspace(0.0, 1.0, 7, endpoint=False):
            b = line(domain, shift=t)
            ints.append(_integrals(b) @ b.psi("lumped"))
        ints = np.array(ints)
        inner = _interior_particles(line(domain), 1.5)  # 1.5 cells inside the unshifted body
        drift[domain] = ((ints.max(axis=0) - ints.min(axis=0)) / b.particles.volume[0])[inner].max()
    assert drift["point"] < 1e-12
    assert 1e-3 < drift["cpdi1"] < 2e-2


@pytest.mark.parametrize("option", ["lumped", "consistent"])
def test_galilean_and_lagrangian_invariance_with_the_grid(option):
    """(x) grid and particles translated together; (xiii) CPDI1 with the grid mapped by a
    stretch and shear; unstructured triangles."""
    t = tri_body(DOMAINS["cpdi1"], length=10.0, offset=OFFSET)
    P = t.psi(option)
    moved = tri_body(DOMAINS["cpdi1"], length=10.0, offset=OFFSET, shift=[0.37, 0.37], grid_moves=True)
    assert np.abs(moved.psi(option) - P).max() < 1e-9
    A = [[1.3, 0.2], [0.0, 0.8]]
    deformed = tri_body(DOMAINS["cpdi1"], length=10.0, offset=OFFSET, A=A, grid_moves=True)
    assert np.abs(deformed.psi(option) - P).max() < 1e-8
    fixed = tri_body(DOMAINS["cpdi1"], length=10.0, offset=OFFSET, A=A)
    assert np.abs(fixed.psi(option) - P).max() > 1e-2


def test_rate_of_the_averaged_basis_under_translation():
    """(xi): dv_ip/dt = G_i . xdot_p holds for GIMP (the average of the gradient is the
    derivative of the average) and fails for CPDI1 (the corner-interpolated gradient is not)."""
    from fempm.transfer.particle_basis import dense_operator

    err = {}
    for domain in ("gimp", "cpdi1"):
        eps = 1e-6
        Sp, Sm = line(domain, shift=0.2 + eps).S, line(domain, shift=0.2 - eps).S
        b = line(domain, shift=0.2)
        _, G = dense_operator(b.V, b.particles, DOMAINS[domain], gradients=True)
        err[domain] = np.abs((Sp - Sm) / (2 * eps) - G[:, :, 0]).max() / np.abs(G).max()
    assert err["gimp"] < 1e-8
    assert err["cpdi1"] > 0.1  # measured 0.32


@pytest.mark.parametrize("option", ["lumped", "consistent"])
def test_functions_equal_the_dense_formula(option):
    """(xiv): Phi_p from the PETSc projection of f_q = delta_pq equals column p of psi."""
    t = tri_body(DOMAINS["gimp"], length=10.0, offset=OFFSET)
    P = t.psi(option)
    pick = _interior_particles(t, 1.5)[:3]
    ids = np.sort(t.particles.ids)[pick]
    for u, k in zip(particle_basis_functions(t.V, t.particles, ids, option=option, domain=DOMAINS["gimp"]), pick):
        assert np.abs(u.x.array - P[:, k]).max() < 1e-10 * np.abs(P[:, k]).max()  # consistent: values up to 3e4 at edge dofs
        assert u.name == f"Phi_{ids[list(pick).index(k)]}"
    with pytest.raises(ValueError, match="unknown option"):
        particle_basis_functions(t.V, t.particles, ids, option="cubic")
