"""The compiled passes of particle domains (fempm.stepping.domain_grid: CPDI1, CPDI2, GIMP)
against the numpy step, their reference: the same state to round-off after every scheme, on
every cell type, inside the mesh and with domains reaching beyond it (CPDI corners clamped onto
the mesh, Gauss points cut), on 1 and 2 ranks (where a step hands samples beyond the ghost cells
to the numpy step)."""

import dolfinx.fem
import dolfinx.mesh as dm
import fempm
import fempm.stepping.consistent
import numpy as np
import pytest
from mpi4py import MPI

from fempm.boundary import slip
from fempm.materials import LinearElastic, NeoHookean
from fempm.materials.newtonian_eos import NewtonianTait
from fempm.stepping import ExplicitSolver, Loads, StepOptions
from fempm.stepping.domain_grid import DomainGrid
from fempm.stepping.grid import SingleFieldGrid

from tests.stepping.test_compiled_step import MESHES, assert_close, make_solver, state


comm = MPI.COMM_WORLD
DOMAINS = {"cpdi1": {"domain": "cpdi1"}, "cpdi2": {"domain": "cpdi2"}, "gimp2": {"domain": "gimp", "gimp_order": 2},
           "cpgimp3": {"domain": "cpgimp", "gimp_order": 3}, "ugimp": {"domain": "ugimp"}, "cpgimp": {"domain": "cpgimp"}}
#: the cells exact GIMP takes the compiled passes on (simplices, axis-aligned boxes)
EXACT_CELLS = ["interval", "triangle", "quadrilateral", "tetrahedron", "hexahedron"]


def run_both(build, steps=12):
    out = []
    for compiled in (False, True):
        solver = build(compiled)
        dts = [solver.step() for _ in range(steps)]
        out.append((state(solver), np.array(dts), solver.j_range, solver.t))
    assert isinstance(solver.grid, DomainGrid)
    return out



def cases(domain, schemes, default):
    """``domain`` on every cell with every scheme: the ``default`` (cell, scheme) pairs in the
    default run, the rest marked slow (each is a numba compilation of its own)."""
    return [pytest.param(cell, scheme, domain, marks=() if (cell, scheme) in default else pytest.mark.slow)
            for cell in MESHES for scheme in schemes]


EXACT_DEFAULT = [("interval", "MUSL", "cpgimp"), ("quadrilateral", "USF", "ugimp"), ("hexahedron", "USL", "cpgimp")]
# the default run: every scheme and every domain at least once, on 1D, 2D and 3D cells (3D with
# CPDI2 and exact GIMP; the other 3D cases, each a dozen seconds of kernels, and the other
# (cell, scheme) pairs in make test-all; exact GIMP on triangles and tetrahedra in
# test_domains_beyond_the_mesh and the consistent mass's cases)
CASES = (cases("cpdi1", ["USL", "MUSL", "USF"], [("triangle", "MUSL")])
         + cases("cpdi2", ["USL", "MUSL"], [("triangle", "MUSL"), ("tetrahedron", "MUSL")])
         + cases("gimp2", ["USL", "MUSL", "USF"], [("triangle", "USL")])
         + [("quadrilateral", "MUSL", "cpgimp3"), pytest.param("tetrahedron", "USL", "cpgimp3", marks=pytest.mark.slow)]
         + [pytest.param(cell, scheme, domain, marks=() if (cell, scheme, domain) in EXACT_DEFAULT else pytest.mark.slow)
            for cell in EXACT_CELLS for scheme in ["USL", "MUSL", "USF"] for domain in ["ugimp", "cpgimp"]])


@pytest.mark.parametrize(("cell", "scheme", "domain"), CASES)
@pytest.mark.parallel(only=("triangle-MUSL-cpdi1", "triangle-MUSL-cpdi2", "hexahedron-USF-gimp2", "interval-MUSL-cpgimp", "quadrilateral-USF-ugimp"))
def test_domain_passes_equal_the_numpy_step(cell, scheme, domain):
    opts = StepOptions(scheme=scheme, flip=0.9, damping=0.5, **DOMAINS[domain])
    ref, got = run_both(lambda compiled: make_solver(cell, opts, compiled=compiled))
    assert np.concatenate(comm.allgather(ref[0][1])).std() > 0.005  # the particles did move differently
    assert_close(ref, got)


#: FMPM's domains, each with its scheme and order
FMPM_DOMAINS = {"cpdi1": ("USL", 2), "cpdi2": ("MUSL", 3), "gimp2": ("MUSL", 2), "cpgimp": ("USL", 3)}


#: FMPM's default cases (every domain on every exact cell in make test-all)
FMPM_DEFAULT = (("cpdi1", "interval"), ("cpdi2", "triangle"))


@pytest.mark.parametrize(("domain", "cell"), [pytest.param(d, c, marks=() if (d, c) in FMPM_DEFAULT else pytest.mark.slow)
                                              for d in FMPM_DOMAINS for c in EXACT_CELLS])
@pytest.mark.parallel(only=("cpdi1-interval", "cpdi2-triangle"))
def test_domain_passes_with_fmpm_equal_the_numpy_step(domain, cell):
    """FMPM(k) with particle domains: M_C y = S^T M S y with the averaged basis S."""
    scheme, order = FMPM_DOMAINS[domain]
    opts = StepOptions(scheme=scheme, flip=0.9, mass="fmpm", fmpm_order=order, **DOMAINS[domain])
    ref, got = run_both(lambda compiled: make_solver(cell, opts, compiled=compiled))
    assert_close(ref, got)


#: the consistent mass's domains, each with its scheme
CONSISTENT_DOMAINS = {"cpdi1": "USL", "cpdi2": "MUSL", "gimp2": "USF", "ugimp": "MUSL", "cpgimp": "USL"}


#: the consistent mass's default cases (the rest of every domain on every cell in make test-all)
CONSISTENT_DEFAULT = (("cpdi2", "triangle"), ("ugimp", "tetrahedron"))


@pytest.mark.parametrize(("domain", "cell"), [pytest.param(d, c, marks=() if (d, c) in CONSISTENT_DEFAULT
                                                           else pytest.mark.slow)
                                              for d in CONSISTENT_DOMAINS for c in EXACT_CELLS])
@pytest.mark.parallel(only=("cpdi1-interval", "cpdi2-triangle", "ugimp-tetrahedron", "cpgimp-quadrilateral"))
def test_domain_passes_with_consistent_mass_equal_the_numpy_step(domain, cell):
    """The consistent mass of the averaged basis, m = S^T diag(M) S (its entries summed over
    each cell's vertex star, fempm.kernels.consistent_domains), in the kept systems."""
    opts = StepOptions(scheme=CONSISTENT_DOMAINS[domain], flip=0.9, mass="consistent", **DOMAINS[domain])
    ref, got = run_both(lambda compiled: make_solver(cell, opts, compiled=compiled), steps=10)
    assert np.concatenate(comm.allgather(ref[0][1])).std() > 0.005
    assert_close(ref, got)


@pytest.mark.parallel
def test_consistent_mass_with_samples_beyond_the_vertex_star_takes_the_numpy_step():
    """CPDI1 domains four cells wide: their corners lie beyond their cell's vertex star, whose
    dofs hold the compiled consistent mass's entries; those steps are the numpy step's, equal to
    the reference."""
    opts = StepOptions(scheme="USL", mass="consistent", domain="cpdi1")

    def build(compiled):
        solver = make_solver("quadrilateral", opts, compiled=compiled)
        p = solver.particles
        p.fields["lp"] = np.full((len(p), 2), 0.2)
        return solver

    ref, got = run_both(build, steps=3)
    assert_close(ref, got)
    solver = build(None)
    assert type(solver.grid.for_step()) is SingleFieldGrid


@pytest.mark.parametrize("wide", ["all", "one"])
@pytest.mark.parallel
def test_consistent_mass_of_domains_wider_than_a_cell_keeps_the_pairs_they_reach(wide, monkeypatch):
    """CPDI1 domains 1.5 cells wide (all, or one of them): corners of one domain lie in cells of
    its vertex star that share no vertex, whose dofs' pairs the domains' sparsity (a cell's own
    dofs by its star dofs, fempm.stepping.mass_sparsity) does not keep; the pass marks the
    cells around them wide (beyond a quarter of the cells with particles: every cell), the
    sparsity keeps their star dofs by star dofs, and the steps equal the numpy step's. (A
    given step: lambda_min(M_L^-1 M_C) is 0.008 with such domains, and its 30-step Lanczos
    estimate, of the stable step, differs by 1e-3 between the two sums' orders.)"""
    if wide == "one":
        monkeypatch.setattr(fempm.stepping.consistent, "WIDE_SHARE", np.inf)  # never every cell
        monkeypatch.setattr(fempm.stepping.consistent, "WIDENINGS", 100)
    opts = StepOptions(scheme="USL", mass="consistent", domain="cpdi1")
    out = []
    for compiled in (False, True):
        solver = make_solver("quadrilateral", opts, compiled=compiled)  # cells 0.1 by 1/9
        p = solver.particles
        p.fields["lp"] = np.full((len(p), 2), 0.075 if wide == "all" else 0.025)
        inside = np.abs((p.x[:, :2] / [0.1, 1.0 / 9.0]) % 1.0 - 0.5)  # corners in the cells on both sides
        p.fields["lp"][np.all(inside < 0.2, axis=1) & (p.ids % 5 == 0)] = 0.075
        dts = [solver.step(3e-4) for _ in range(4)]
        out.append((state(solver), np.array(dts), solver.j_range, solver.t))
    assert_close(*out)
    systems = solver.grid.mass.systems
    assert type(solver.grid) is DomainGrid
    count = comm.allreduce(len(systems.wide))
    total = comm.allreduce(systems.num_cells)
    assert count > 0.5 * total if wide == "all" else 0 < count < 0.5 * total
    assert np.all(systems.slot[systems.pattern[systems.wide]] < systems.nnz)  # their pairs kept
    if wide == "one":
        assert comm.allreduce(int(np.count_nonzero(systems.slot == systems.nnz))) > 0  # the others' not all


def filled(cell: str, options: StepOptions, compiled: bool) -> ExplicitSolver:
    """Particles in every cell, domains larger than their sub-cells: the boundary ones reach
    beyond the mesh; a law without a kernel on half of them."""
    mesh = MESHES[cell]()
    d = mesh.geometry.dim
    p = fempm.create_particles(mesh, 2 ** d, density=1.0, jitter=0.0 if options.particle_domain.tracks_corners else 0.3, seed=5,
                               corners=options.particle_domain.tracks_corners)
    p.fields["lp"] = 1.6 * 0.5 * p.volume[:, None] ** (1.0 / d) * np.ones((1, d))
    p.fields["v"] = 0.3 * np.sin(np.pi * p.x) * np.cos(2.0 * p.x[:, ::-1])  # no normal velocity at the walls
    p.fields["body"] = (p.x[:, 0] > 0.5).astype(np.int32)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (d,)))
    bcs = [slip(V, lambda x: np.isclose(x[0], 0.0), np.eye(d)[0])]
    materials = [NeoHookean(30.0, 0.3), NewtonianTait(rho0=1.0, kappa=20.0, viscosity=0.05)]
    return ExplicitSolver(V, p, materials, bcs=bcs, loads=Loads(body_force=-np.eye(d)[d - 1]), options=options,
                          compiled=compiled)


BEYOND = [("interval", "cpdi1"), ("triangle", "cpdi2"), ("quadrilateral", "ugimp"), ("tetrahedron", "cpgimp")]


@pytest.mark.parametrize(("cell", "domain"), [pytest.param(c, d, marks=() if (c, d) in BEYOND else pytest.mark.slow)
                                              for c in MESHES for d in ("cpdi1", "cpdi2", "gimp2")]
                         + [pytest.param(c, d, marks=() if (c, d) in BEYOND else pytest.mark.slow)
                            for c in EXACT_CELLS for d in ("ugimp", "cpgimp")])
@pytest.mark.parallel(only=("interval-cpdi1", "triangle-cpdi2", "quadrilateral-ugimp"))
def test_domains_beyond_the_mesh(cell, domain):
    opts = StepOptions(scheme="MUSL", flip=0.95, **DOMAINS[domain])
    ref, got = run_both(lambda compiled: filled(cell, opts, compiled), steps=8)
    assert_close(ref, got)


@pytest.mark.parallel
def test_samples_beyond_the_ghost_cells_take_the_numpy_step():
    """On several ranks a step whose samples some rank holds in no local cell is the numpy
    step's; the others are the compiled passes'."""
    solver = make_solver("triangle", StepOptions(domain="cpdi1"))
    grid = solver.grid
    taken = []
    for _ in range(3):
        step_grid = grid.for_step()
        taken.append(type(step_grid))
        solver.step()
    if comm.size == 1:
        assert taken == [DomainGrid] * 3
    else:
        assert set(taken) <= {DomainGrid, SingleFieldGrid}


@pytest.mark.parametrize("ghosts", [False, True])
@pytest.mark.parallel
def test_exact_gimp_on_a_mesh_distributed_by_particles(ghosts, monkeypatch):
    """On a mesh distributed by particles a rank holds its own cells (and, with ``ghosts``, the
    cells sharing a vertex with them): a box reaching cells the rank does not have takes the
    numpy step, never a box cut at the partition as if at the mesh's boundary; with the ghosts
    every step takes the compiled passes."""
    from fempm.particles.partition import particle_balanced

    def balanced():
        seeds = np.random.default_rng(2).uniform(0.2, 0.8, (400, 2))
        return particle_balanced(dm.create_unit_square(comm, 12, 10), seeds if comm.rank == 0 else np.zeros((0, 2)),
                                 ghosts=ghosts)

    monkeypatch.setitem(MESHES, "balanced triangle", balanced)

    def build(compiled):
        return make_solver("balanced triangle", StepOptions(scheme="MUSL", flip=0.9, domain="cpgimp"), compiled=compiled)

    ref, got = run_both(build, steps=6)
    assert_close(ref, got)
    solver = build(True)
    taken = {type(solver.grid.for_step()) for _ in range(2) if solver.step()}
    assert taken == {DomainGrid} if ghosts or comm.size == 1 else taken <= {DomainGrid, SingleFieldGrid}


@pytest.mark.parallel
def test_domain_grid_needs_sample_points():
    mesh = dm.create_unit_square(comm, 4, 4)
    p = fempm.create_particles(mesh, 4)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    for opts, expected in [(StepOptions(domain="cpdi1"), DomainGrid),
                           (StepOptions(domain="cpdi1", mass="consistent"), DomainGrid),
                           (StepOptions(domain="ugimp"), DomainGrid),
                           (StepOptions(domain="cpgimp", mass="consistent"), DomainGrid),
                           (StepOptions(domain="cpdi1", transfer="apic"), SingleFieldGrid),
                           (StepOptions(domain="cpdi1", mass="fmpm", fmpm_order=2), DomainGrid),
                           (StepOptions(domain="gimp", gimp_order=2), DomainGrid)]:
        assert type(ExplicitSolver(V, p, [LinearElastic(1.0, 0.3)], options=opts).grid) is expected
