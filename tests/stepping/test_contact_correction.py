"""The nodal contact correction (fempm.stepping.contact.correct): momentum conserved to round-off, no
approach left, Coulomb's stick and slip, separation free."""

import numpy as np
import pytest

from fempm.stepping.contact import Contact, correct


def _two_groups(n=500, d=2, seed=0):
    rng = np.random.default_rng(seed)
    m = rng.uniform(0.1, 2.0, (2, n))
    m[rng.random((2, n)) < 0.2] = 0.0  # some nodes hold one group only
    v = rng.standard_normal((2, n, d))
    v[m == 0.0] = 0.0
    grad = rng.standard_normal((2, n, d))
    return m, v, grad


@pytest.mark.parametrize("friction", [0.0, 0.3, 1e6])
@pytest.mark.parametrize("d", [2, 3])
def test_momentum_is_conserved_and_no_group_approaches_after_the_correction(friction, d):
    m, v, grad = _two_groups(d=d)
    before = np.einsum("gn,gnd->nd", m, v)
    contact = correct(m, v, grad, friction)
    assert contact.sum() > 100 and np.all(contact == (m > 0).all(axis=0))
    after = np.einsum("gn,gnd->nd", m, v)
    np.testing.assert_allclose(after, before, rtol=0, atol=1e-14 * np.abs(before).max())
    total = m.sum(axis=0)
    vcm = after / np.where(total > 0, total, 1.0)[:, None]
    for g in range(2):
        n = 2 * grad[g] - grad.sum(axis=0)
        n /= np.linalg.norm(n, axis=1)[:, None]
        wn = np.einsum("nd,nd->n", v[g] - vcm, n)
        assert np.all(wn[contact] <= 1e-13)


def test_stick_slip_and_separation():
    """One node, group 0 (mass 1) moving at (1, 0.5) into group 1 (mass 3, at rest) whose
    outward normal is -x: the normal relative velocity goes; the tangential one stays without
    friction, is reduced by mu times the normal one, or stops (stick) when mu is large; moving
    apart, nothing changes."""
    m = np.array([[1.0], [3.0]])
    grad = np.array([[[1.0, 0.0]], [[-1.0, 0.0]]])  # out of group 0: +x
    vcm = np.array([0.25, 0.125])
    for mu, expect0 in [(0.0, [0.25, 0.5]), (0.2, [0.25, 0.5 - 0.2 * 0.75]), (1.0, vcm)]:
        v = np.array([[[1.0, 0.5]], [[0.0, 0.0]]])
        correct(m, v, grad, mu)
        np.testing.assert_allclose(v[0, 0], expect0, rtol=1e-14)
        np.testing.assert_allclose(m[0, 0] * v[0, 0] + m[1, 0] * v[1, 0], [1.0, 0.5], rtol=1e-14)
    v = np.array([[[-1.0, 0.5]], [[0.0, 0.0]]])  # separating
    correct(m, v, grad, 0.5)
    np.testing.assert_array_equal(v, [[[-1.0, 0.5]], [[0.0, 0.0]]])


def test_a_rigid_group_keeps_its_velocity_and_its_normal_and_the_others_take_its_velocity():
    """Group 1 rigid (moving at (0.5, 0) with a normal +y out of it; its mass does not count)
    under group 0 falling at (2, -1) onto it, whose own mass gradient leans (a corner): the
    normal is the rigid body's, so the fall stops, the tangential velocity relative to the
    rigid body is cut by mu times the fall or sticks to it; the rigid velocity is unchanged."""
    m = np.array([[1.0], [1e-3]])
    grad = np.array([[[0.7, -0.7]], [[0.0, 1.0]]])
    for mu, expect0 in [(0.0, [2.0, 0.0]), (0.5, [2.0 - 0.5, 0.0]), (2.0, [0.5, 0.0])]:
        v = np.array([[[2.0, -1.0]], [[0.5, 0.0]]])
        correct(m, v, grad, mu, rigid=np.array([False, True]))
        np.testing.assert_allclose(v[0, 0], expect0, rtol=1e-14, atol=1e-15)
        np.testing.assert_array_equal(v[1, 0], [0.5, 0.0])
    v = np.array([[[2.0, 1.0]], [[0.5, 0.0]]])  # leaving the rigid body
    correct(m, v, grad, 0.5, rigid=np.array([False, True]))
    np.testing.assert_array_equal(v, [[[2.0, 1.0]], [[0.5, 0.0]]])


def test_the_position_check_corrects_only_groups_that_touch():
    """Three nodes where group 0 moves at +x into group 1 at rest (normal +x out of group 0):
    the groups' nodal centres of mass are 0.5, 1.0 and 1.5 apart along the normal; with a gap of
    1.0 only the first is in contact, and a step of dt = 0.25 at the approach speed 1 (relative
    to group 1, whose mass counts: the node's centre-of-mass speed is 0.5) brings the second
    within it too. Without a gap all three are corrected."""
    m = np.ones((2, 3))
    grad = np.array([[[1.0, 0.0]] * 3, [[-1.0, 0.0]] * 3])
    x0 = np.zeros((3, 2))
    x1 = np.array([[0.5, 0.3], [1.0, -0.2], [1.5, 0.0]])  # offsets along the tangent do not count
    moments = np.stack([x0, x1])  # unit masses: the moments are the centres of mass
    for gap, dt, touching in [(None, 0.0, [1, 1, 1]), (1.0, 0.0, [1, 0, 0]), (1.0, 0.25, [1, 1, 0])]:
        v = np.zeros((2, 3, 2))
        v[0, :, 0] = 1.0
        correct(m, v, grad, 0.0, moments=moments, gap=gap, dt=dt)
        np.testing.assert_array_equal(v[0, :, 0] == 0.5, np.array(touching, bool))  # corrected: both at v_cm
        np.testing.assert_allclose(v[0, :, 0] + v[1, :, 0], 1.0, rtol=1e-15)  # momentum kept either way


def test_nodes_touching_a_rigid_body_share_its_normal_impulse_by_depth():
    """A rigid body at rest below four nodes of group 0 (mass 1, 2, 1, 1; normal -y into the
    rigid body; its nodal centre of mass at y = -0.3), whose own centres are at y = 0.1, 0,
    0.2 and 0.9: with a gap of 0.6 their depths are 0.2, 0.3, 0.1 and -0.6, so nodes 0-2 touch
    (one patch) and node 3 does not. Nodes 0 and 1 move into it at 0.5 and 0.2, node 2 leaves
    at 0.1, all at 1 along x. The patch takes P = 1 * 0.5 + 2 * 0.2 = 0.9 of normal momentum,
    shared by the approaching nodes as dv_n = P d / sum(m d) (sum(m d) = 1 * 0.2 + 2 * 0.3 =
    0.8): 0.225 and 0.3375, so node 0 keeps 0.275 of its approach and node 1 leaves at 0.1375;
    friction takes mu dv_n of the tangential speed, or all of it (stick); node 2 separates
    freely. Without patches each node is on its own: 0 and 1 stop."""
    m = np.array([[1.0, 2.0, 1.0, 1.0], [1e-3] * 4])
    grad = np.array([[[0.3, -1.0]] * 4, [[0.0, 1.0]] * 4])  # the rigid body's gradient: +y out of it
    y = np.array([0.1, 0.0, 0.2, 0.9])
    centres = np.stack([np.stack([np.zeros(4), y], axis=1), np.tile([0.0, -0.3], (4, 1))])
    moments = m[:, :, None] * centres
    rigid = np.array([False, True])

    def one_patch(dofs, values):  # nodes 0-2 (node 3 is never asked: it does not touch)
        assert set(dofs) <= {0, 1, 2}
        return np.broadcast_to(values.sum(axis=0), values.shape)

    for mu, patches, expect in [
        (0.5, one_patch, [[1.0 - 0.5 * 0.225, -0.275], [1.0 - 0.5 * 0.3375, 0.1375], [1.0, 0.1], [1.0, -1.0]]),
        (20.0, one_patch, [[0.0, -0.275], [0.0, 0.1375], [1.0, 0.1], [1.0, -1.0]]),
        (0.5, None, [[0.75, 0.0], [0.9, 0.0], [1.0, 0.1], [1.0, -1.0]]),
    ]:
        v = np.zeros((2, 4, 2))
        v[0] = before = [[1.0, -0.5], [1.0, -0.2], [1.0, 0.1], [1.0, -1.0]]
        correct(m, v, grad, mu, rigid, moments, gap=0.6, patches=patches)
        np.testing.assert_allclose(v[0], expect, rtol=0, atol=1e-15)
        np.testing.assert_array_equal(v[1], 0.0)
        taken = m[0] @ (v[0, :, 1] - np.array(before)[:, 1])  # the normal momentum the rigid body took:
        assert taken == pytest.approx(0.9, rel=1e-14)  # shared or node by node, 1 * 0.5 + 2 * 0.2


def test_bad_options():
    with pytest.raises(ValueError, match="friction"):
        Contact(friction=-0.1)
    with pytest.raises(ValueError, match="mass_cutoff"):
        Contact(mass_cutoff=1.0)
    with pytest.raises(ValueError, match="rigid"):
        Contact(rigid=(-1,))
    with pytest.raises(ValueError, match="gap"):
        Contact(gap=0.0)
