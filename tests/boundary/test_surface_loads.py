"""Pressure and traction on tagged parts of the body's surface (fempm.boundary.surface): the total
force exact on triangles, quadrilaterals, tetrahedra and hexahedra (structured and gmsh, 1 to 27
particles per cell), a plate under a pressure carrying it (quasi-static, below the loaded row the
stress is -p), the pressure normal to the surface as the plate turns while the traction keeps its
direction, Nanson's cofactor, serial = 2 ranks; the errors."""

import dolfinx.mesh as dm
import numpy as np
import pytest
from mpi4py import MPI

import fempm
from fempm.boundary import SurfaceLoad, slip, surface_load
from fempm.boundary.surface import cofactor_apply
from fempm.materials import LinearElastic, NeoHookean
from fempm.meshes import tagged_polygon
from fempm.scene import Scene, run
from fempm.stepping import Loads, StepOptions
from fempm.stepping.loads import external_forces


CELLS = {"triangle": 2, "quadrilateral": 2, "tetrahedron": 3, "hexahedron": 3}
TOP = 2


def tagged_box(cell, n, comm=MPI.COMM_WORLD, height=1.25, top=1.0):
    """The unit square (cube) of ``n`` cells a side stretched to ``height``, the facets of the
    plane x_d = ``top`` tagged TOP (inside the mesh when ``top`` < ``height``)."""
    d = CELLS[cell]
    kind = getattr(dm.CellType, cell)
    if d == 2:
        mesh = dm.create_rectangle(comm, [[0, 0], [1, height]], [n, round(n * height)], kind)
    else:
        mesh = dm.create_box(comm, [[0, 0, 0], [1, 1, height]], [n, n, round(n * height)], kind)
    mesh.topology.create_entities(d - 1)
    facets = dm.locate_entities(mesh, d - 1, lambda x: np.isclose(x[d - 1], top))
    return mesh, dm.meshtags(mesh, d - 1, np.sort(facets), np.full(len(facets), TOP, dtype=np.int32))


def total(p, load, t=0.0):
    return p.comm.allreduce(load.forces(p, t).sum(axis=0))


@pytest.mark.parametrize("cell", list(CELLS))
@pytest.mark.parallel(only=("triangle", "tetrahedron"))
def test_the_total_force_is_exact_on_every_cell_type(cell):
    d = CELLS[cell]
    mesh, tags = tagged_box(cell, 4)
    for n in (1, 2, 3):
        p = fempm.create_particles(mesh, n**d, cells=lambda x: x[d - 1] < 1.0)  # the body below the tag
        p.fields["F"] = np.tile(np.eye(d), (len(p), 1, 1))
        press = surface_load(p, tags, TOP, pressure=3.0)
        np.testing.assert_allclose(total(p, press), -3.0 * np.eye(d)[d - 1], rtol=0, atol=1e-13)
        shear = surface_load(p, tags, TOP, traction=np.eye(d)[0] * 2.0)  # shares the area vectors
        np.testing.assert_allclose(total(p, shear), 2.0 * np.eye(d)[0], rtol=0, atol=1e-13)
        A = p.fields["surface_2"]
        loaded = np.any(A != 0, axis=1)
        row = p.comm.allreduce(float(p.x[loaded, d - 1].min(initial=1.0)), op=MPI.MIN)
        assert row > 1.0 - 1.0 / (4 * n)  # only the row nearest the surface


@pytest.mark.parametrize("quadrilateral", [False, True], ids=["triangles", "quadrilaterals"])
@pytest.mark.parallel(only=("triangles",))
def test_the_total_force_is_exact_on_a_gmsh_body_with_an_inclined_top(quadrilateral):
    vertices = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.7], [0.0, 1.2]])  # the top inclined
    data = tagged_polygon(MPI.COMM_WORLD, vertices, 0.1, [0, 0, 5, 0], quadrilateral=quadrilateral)
    p = fempm.create_particles(data.mesh, 4)
    p.fields["F"] = np.tile(np.eye(2), (len(p), 1, 1))
    edge = vertices[3] - vertices[2]
    outward = np.array([edge[1], -edge[0]])  # |outward| = the edge's length
    np.testing.assert_allclose(total(p, surface_load(p, data.facet_tags, 5, pressure=2.0)), -2.0 * outward,
                               atol=1e-13)


@pytest.mark.parametrize("cell", ["triangle", "quadrilateral", "tetrahedron"])
def test_a_plate_carries_the_pressure_on_its_tagged_top(cell):
    """The unit plate on a slip floor between slip walls (uniaxial strain), a pressure p on its
    top, one quasi-static step: below the loaded row of cells the stress is -p (the load enters
    through the particles of that row; exact on the tensor cells, 2e-6 on simplices)."""
    d, p_top, n = CELLS[cell], 1e-3, 4
    mesh, tags = tagged_box(cell, n, height=1.0)
    p = fempm.create_particles(mesh, 2**d)
    loads = Loads(surface=[surface_load(p, tags, TOP, pressure=p_top)])

    def walls(V):
        return [slip(V, lambda x, k=k: np.isclose(x[k], 0.0) | np.isclose(x[k], 1.0) if k < d - 1
                     else np.isclose(x[k], 0.0), np.eye(d)[k]) for k in range(d)]

    scene = Scene(name="plate", mesh=mesh, particles=p, materials=[LinearElastic(1.0, 0.3)], t_end=1.0, bcs=walls,
                  loads=loads, frames=0, options=StepOptions(integrator="implicit", dynamics="quasi-static"))
    s = scene.solver()
    s.step(1.0)
    below = p.x[:, d - 1] < 1.0 - 1.0 / n
    syy = p.comm.allreduce(float(p.fields["sigma"][below, d - 1, d - 1] @ p.volume[below]))
    assert syy / p.comm.allreduce(float(p.volume[below].sum())) == pytest.approx(-p_top, rel=1e-5)
    # the follower load on the deformed top (strain 1e-3, its particles' F a little uneven)
    np.testing.assert_allclose(p.comm.allreduce(external_forces(loads, p, 1.0).sum(axis=0)),
                               -p_top * np.eye(d)[d - 1], atol=1e-3 * p_top)


def spinning_plate(load: str, comm=MPI.COMM_WORLD, cell="quadrilateral"):
    """A stiff square plate 0.25 wide spinning at one turn per second in the unit square, a
    pressure (or a traction) 0.1 on its top."""
    mesh = dm.create_rectangle(comm, [[0, 0], [1, 1]], [16, 16], getattr(dm.CellType, cell))
    mesh.topology.create_entities(1)
    lo, hi = 0.375, 0.625
    facets = dm.locate_entities(mesh, 1, lambda x: np.isclose(x[1], hi) & (x[0] > lo - 1e-9) & (x[0] < hi + 1e-9))
    tags = dm.meshtags(mesh, 1, np.sort(facets), np.full(len(facets), TOP, dtype=np.int32))
    p = fempm.create_particles(mesh, 4, cells=lambda x: (x[0] > lo) & (x[0] < hi) & (x[1] > lo) & (x[1] < hi))
    r = p.x - 0.5
    p.fields["v"] = 2 * np.pi * np.stack([-r[:, 1], r[:, 0]], axis=1)
    value = {"pressure": 0.1} if load == "pressure" else {"traction": np.array([0.0, -0.1])}
    loads = Loads(surface=[surface_load(p, tags, TOP, **value)])
    return Scene(name="spin", mesh=mesh, particles=p, materials=[NeoHookean(1e4, 0.3)], t_end=0.2, loads=loads,
                 frames=0)


def top_normal(p):
    """The outward unit normal of the line through the loaded particles (all ranks)."""
    loaded = np.any(p.fields["surface_2"] != 0, axis=1)
    xs = np.concatenate(p.comm.allgather(p.x[loaded]))
    centre = p.comm.allreduce(p.x.sum(axis=0)) / p.num_global
    tangent = np.linalg.svd(xs - xs.mean(axis=0))[2][0]
    n = np.array([-tangent[1], tangent[0]])
    return n if n @ (xs.mean(axis=0) - centre) > 0 else -n


@pytest.mark.parametrize("cell", ["quadrilateral", "triangle"])
def test_the_pressure_stays_normal_to_the_surface_as_the_plate_turns(cell):
    scene = spinning_plate("pressure", cell=cell)
    p = scene.particles
    run(scene, None, progress=False)
    f = p.comm.allreduce(external_forces(scene.loads, p, scene.t_end).sum(axis=0))
    n = top_normal(p)
    turned = np.degrees(np.arctan2(-n[0], n[1]))
    assert turned > 45.0  # the plate has turned (by less than 72 degrees: the grid's transfers damp the spin)
    assert np.degrees(np.arccos(-f @ n / np.linalg.norm(f))) < 1.0  # along the inward normal
    assert np.linalg.norm(f) == pytest.approx(0.1 * 0.25, rel=5e-3)  # p times the (nearly) unstretched width


def test_a_traction_keeps_its_direction_and_total_as_the_plate_turns():
    scene = spinning_plate("traction")
    p = scene.particles
    run(scene, None, progress=False)
    np.testing.assert_allclose(p.comm.allreduce(external_forces(scene.loads, p, scene.t_end).sum(axis=0)),
                               [0.0, -0.1 * 0.25], atol=1e-14)


@pytest.mark.parallel
def test_two_ranks_turn_the_plate_as_one():
    comm = MPI.COMM_WORLD
    ends = []
    for c in (comm, MPI.COMM_SELF):
        scene = spinning_plate("pressure", comm=c)
        run(scene, None, progress=False)
        p = scene.particles
        ends.append(c.allreduce(external_forces(scene.loads, p, scene.t_end).sum(axis=0)))
    np.testing.assert_allclose(ends[0], ends[1], rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize("d", [2, 3])
def test_the_cofactor_is_nanson(d):
    rng = np.random.default_rng(1)
    F = np.eye(d) + 0.4 * rng.standard_normal((20, d, d))
    A = rng.standard_normal((20, d))
    want = np.einsum("n,nji,nj->ni", np.linalg.det(F), np.linalg.inv(F), A)  # J F^-T A
    np.testing.assert_allclose(cofactor_apply(F, A), want, rtol=1e-12, atol=1e-12)


@pytest.mark.parallel
def test_bad_surface_loads_are_named():
    mesh, tags = tagged_box("quadrilateral", 4)
    p = fempm.create_particles(mesh, 4, cells=lambda x: x[1] < 1.0)
    with pytest.raises(ValueError, match=r"unknown facet tag 7: it marks no facets on any rank \(the facet tags hold 2\)"):
        surface_load(p, tags, 7, pressure=1.0)
    with pytest.raises(ValueError, match="a pressure or a traction"):
        surface_load(p, tags, TOP)
    with pytest.raises(ValueError, match="a pressure or a traction"):
        surface_load(p, tags, TOP, pressure=1.0, traction=[1.0, 0.0])
    with pytest.raises(ValueError, match=r"traction=\[1.0, 0.0, 0.0\] must be 2 finite components"):
        surface_load(p, tags, TOP, traction=[1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="pressure=nan must be a finite number"):
        surface_load(p, tags, TOP, pressure=float("nan"))
    through = fempm.create_particles(mesh, 4)  # the body fills the mesh: the tag runs through it
    with pytest.raises(ValueError, match=r"facet tag 2 runs through the body: 4 of its facets have particles on both"):
        surface_load(through, tags, TOP, pressure=1.0)
    low = fempm.create_particles(mesh, 4, cells=lambda x: x[1] < 0.5)  # nowhere near the tag
    with pytest.raises(ValueError, match="facet tag 2 marks no part of the body's surface"):
        surface_load(low, tags, TOP, pressure=1.0)
    cells = dm.meshtags(mesh, 2, np.arange(2, dtype=np.int32), np.full(2, 1, dtype=np.int32))
    with pytest.raises(ValueError, match=r"need facet tags \(dimension 1\)"):
        surface_load(p, cells, 1, pressure=1.0)
    p.fields["F"] = np.tile(np.eye(2), (len(p), 1, 1))
    with pytest.raises(ValueError, match=r"the particles carry no field 'surface_2' \(made by surface_load\)"):
        SurfaceLoad("surface_2", pressure=1.0).forces(p, 0.5)
    surface_load(p, tags, TOP, pressure=1.0)
    with pytest.raises(ValueError, match=r"the pressure on 'surface_2' is inf at t = 0.5"):
        SurfaceLoad("surface_2", pressure=lambda t: np.inf).forces(p, 0.5)
