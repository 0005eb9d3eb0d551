"""Hanging block under extreme self-weight (docs/verification.md), structured quads,
3x3 particles per cell: standard MPM separates, CPDI1 stretches continuously."""

from fempm.scenes import hanging_block, largest_neighbour_gap


def gap_history(domain, t_end):
    scene = hanging_block(domain=domain, t_end=t_end)
    solver, p, h = scene.solver(), scene.particles, scene.params["h"]
    gaps, bottom = [], 0.0
    while solver.t < t_end:
        solver.step(dt_max=t_end - solver.t)
        gaps.append(largest_neighbour_gap(p) / h)
        bottom = min(bottom, p.x[:, 1].min())
    return gaps, bottom


def test_point_separates_cpdi1_stays_continuous():
    point, _ = gap_history("point", 0.05)
    cpdi, bottom = gap_history("cpdi1", 0.15)
    assert point[-1] > 5.0  # measured 7.1 cell sizes at t = 0.047: the lower rows fall away
    assert max(cpdi) < 2.0  # measured 1.51: neighbours stay within two cells while it stretches
    assert bottom < -2.0  # the block has stretched to over twice its length (measured -2.58 at t = 0.09)


def test_cpdi2_survives_the_rebound_on_triangles():
    """Unstructured triangles, through the rebound: CPDI2 lattice squares (corners moved with
    the grid) stay continuous up to t = 0.3, past t = 0.27 where CPDI1's parallelograms, which
    only follow the particle's F, leave the mesh (measured with demos/hanging_block.py --t-end 0.5)."""
    scene = hanging_block(domain="cpdi2", mesh="unstructured", t_end=0.3)
    solver, p, h = scene.solver(), scene.particles, scene.params["h"]
    gaps, bottom = [], 0.0
    while solver.t < 0.3:
        solver.step(dt_max=0.3 - solver.t)
        gaps.append(largest_neighbour_gap(p) / h)
        bottom = min(bottom, p.x[:, 1].min())
    assert max(gaps) < 2.0  # measured 1.60
    assert bottom < -2.4  # measured -2.58
