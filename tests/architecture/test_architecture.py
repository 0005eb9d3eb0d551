"""The examples of docs/architecture.md ("Where things plug in") run: a law, a mass model, a
particle domain, a scheme and a grid condition, each defined outside the package and taken by
the one step skeleton as given."""

import re
import types
from pathlib import Path

import dolfinx.fem as fem
import dolfinx.mesh as dm
import numpy as np
import pytest
from mpi4py import MPI

import fempm
from fempm.boundary import fixed
from fempm.materials import LinearElastic
from fempm.stepping import ExplicitSolver, StepOptions
from fempm.stepping.state import StepState

pytestmark = pytest.mark.xdist_group("test_architecture")  # one worker computes its module fixtures

comm = MPI.COMM_WORLD
PAGE = Path(__file__).resolve().parents[2] / "docs" / "architecture.md"


@pytest.fixture(scope="module")
def examples() -> dict:
    """The page's python blocks after "## Where things plug in", run in one namespace."""
    text = PAGE.read_text().split("## Where things plug in", 1)[1]
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) == 6
    for block in blocks:  # each example is short: under 30 lines
        assert len(block.strip().splitlines()) < 30
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, str(PAGE), "exec"), namespace)
    return namespace


def solver(options=None, law=None, bcs=None, cells=6, colliders=()):
    """A small elastic square moving and shearing, on triangles."""
    options = StepOptions() if options is None else options
    mesh = dm.create_rectangle(comm, [[0.0, 0.0], [2.0, 2.0]], [2 * cells, 2 * cells], dm.CellType.triangle)
    V = fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    p = fempm.create_particles(mesh, 4, density=1000.0, cells=lambda x: (x[0] > 0.5) & (x[0] < 1.5)
                               & (x[1] > 0.5) & (x[1] < 1.5))
    p.fields["v"] = np.column_stack([0.1 + 0.2 * p.x[:, 1], -0.1 * p.x[:, 0]])
    law = law or LinearElastic(1e5, 0.3)
    return ExplicitSolver(V, p, [law], bcs=bcs(V) if bcs else (), options=options, colliders=colliders)


def run(s, steps=3, dt=None):
    for _ in range(steps):
        s.step(dt)
    return s


def total_momentum(s):
    return s.particles.comm.allreduce(s.particles.mass @ s.particles.fields["v"])


def test_a_law_plugs_in(examples):
    toy = run(solver(law=examples["SmallStrain"](1e5, 0.3), options=StepOptions(scheme="USL")), dt=1e-3)
    elastic = run(solver(options=StepOptions(scheme="USL")), dt=1e-3)
    assert np.abs(toy.particles.fields["sigma"] - elastic.particles.fields["sigma"]).max() < 1e-9 * 1e5


def test_a_mass_model_plugs_in(examples):
    cautious = solver(StepOptions(mass=examples["CautiousLumped"]()))
    assert cautious.options.mass_model.label == "lumped/2"
    plain = solver()
    assert np.isclose(cautious.step(), 0.5 * plain.step(), rtol=1e-12)


def test_a_particle_domain_plugs_in(examples):
    s = solver(StepOptions(domain=examples["TwoPoints"]()))
    before = total_momentum(s)
    run(s)
    assert np.abs(total_momentum(s) - before).max() < 1e-10 * np.abs(before).max()  # no load, no condition
    assert np.isfinite(s.particles.fields["sigma"]).all() and s.step_count == 3


def test_a_scheme_plugs_in(examples):
    split = run(solver(StepOptions(scheme=examples["SplitUSL"]())), dt=1e-3)
    usl = run(solver(StepOptions(scheme="USL")), dt=1e-3)
    for field in ("v", "sigma", "F"):
        assert np.abs(split.particles.fields[field] - usl.particles.fields[field]).max() < 1e-12
    assert np.abs(split.particles.x - usl.particles.x).max() < 1e-14


def test_a_grid_condition_plugs_in(examples):
    def held(V):  # every dof scaled by 0: the grid stands still, and the particles with it
        return [examples["Damper"](fixed(V, lambda x: np.full(x.shape[1], True)).dofs, keep=0.0)]

    s = solver(StepOptions(scheme="USL", flip=0.0), bcs=held)
    x0 = s.particles.x.copy()
    run(s, dt=1e-3)
    assert np.abs(s.particles.x - x0).max() == 0.0 and np.abs(s.particles.fields["v"]).max() == 0.0


def test_a_collider_shape_plugs_in(examples):
    """An ellipse of one's own, moving down onto the square, pushes it: the square's momentum
    changes by the impulse the collider takes, and a shape without the protocol is refused."""
    from fempm.colliders import Collider, Shape

    ellipse = examples["Ellipse"]((1.0, 1.85), 0.6, 0.3)
    assert isinstance(ellipse, Shape)
    assert ellipse.distance(np.array([[1.0, 1.55], [1.6, 1.85]])) == pytest.approx([0.0, 0.0], abs=1e-12)
    s = solver(StepOptions(), colliders=[Collider(ellipse, velocity=(0.0, -2.0))])
    p0 = total_momentum(s)
    run(s, steps=25)
    impulse = s.collisions.total_impulse
    assert impulse[1] > 0.0  # the collider took upward momentum: the body was pushed down
    assert total_momentum(s) == pytest.approx(p0 - impulse, abs=1e-9 * np.abs(impulse).max())
    with pytest.raises(TypeError, match="lacks normal_at"):
        Collider(type("Blob", (), {"dim": 2, "distance": lambda self, x: x[:, 0]})())



def held_by(root) -> list:
    """The fempm objects, containers and closures reachable from ``root`` through what they hold
    (instances' attributes, containers' items, bound methods, closures' cells), not through
    classes or modules."""
    seen, todo, out = {id(root)}, [root], []
    while todo:
        obj = todo.pop()
        out.append(obj)
        if isinstance(obj, types.FunctionType):
            refs = [c.cell_contents for c in obj.__closure__ or ()] + list(obj.__defaults__ or ())
        elif isinstance(obj, types.MethodType):
            refs = [obj.__self__, obj.__func__]
        elif isinstance(obj, dict):
            refs = [*obj.keys(), *obj.values()]
        elif isinstance(obj, (list, tuple, set)):
            refs = list(obj)
        else:
            refs = list(getattr(obj, "__dict__", {}).values())
            refs += [getattr(obj, k) for k in getattr(type(obj), "__slots__", ()) if hasattr(obj, k)]
        for ref in refs:
            kept = (isinstance(ref, (dict, list, tuple, set, types.MethodType, types.FunctionType))
                    or type(ref).__module__.startswith("fempm"))
            if kept and not isinstance(ref, type) and id(ref) not in seen:
                seen.add(id(ref))
                todo.append(ref)
    return out


@pytest.mark.parametrize("case", ["point", "consistent", "fmpm", "cpdi", "numpy", "contact", "implicit"])
def test_the_steps_parts_do_not_hold_the_solver(case):
    """The grids, their nodal masses and the implicit step read a StepState: none of them holds
    the solver (nor reaches it through what it holds)."""
    options = {"consistent": StepOptions(mass="consistent"), "fmpm": StepOptions(mass="fmpm2"),
               "cpdi": StepOptions(domain="cpdi1"), "implicit": StepOptions(integrator="implicit")}
    s = solver(options.get(case))
    if case == "numpy":
        s.compiled = False
    if case == "contact":
        s.contact = fempm.Contact()
    s.step(1e-3)
    part = s.implicit if case == "implicit" else s.grid
    expected = {"point": "PointGrid", "consistent": "PointGrid", "fmpm": "PointGrid", "cpdi": "DomainGrid",
                "numpy": "SingleFieldGrid", "contact": "ContactPointGrid", "implicit": "ImplicitStep"}[case]
    assert type(part).__name__ == expected
    objects = held_by(part)
    assert any(isinstance(o, StepState) for o in objects)
    assert not [o for o in objects if isinstance(o, ExplicitSolver)]
