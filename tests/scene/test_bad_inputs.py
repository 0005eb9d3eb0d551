"""Bad inputs to the materials, boundary conditions, particles, loads, options, scenes, the step
and the run, in one table: each gives a clear error of a given class whose message names the
problem, never a silent NaN, an endless run, a step that goes backwards or a traceback from
deep inside numpy. The command line's usage errors are in test_cli_options.py."""

import dataclasses

import dolfinx.fem
import dolfinx.mesh as dm
import numpy as np
import pytest
from mpi4py import MPI

import fempm
import fempm.materials
import fempm.meshes
import fempm.scenes
from fempm.boundary import friction, prescribed, slip
from fempm.io.checkpoint import CheckpointError
from fempm.stepping.health import Health
from fempm.io import OutputFolderError, OutputSizeError
from fempm.particles.location import OutsideMeshError
from fempm.meshes import MeshFileError
from fempm.materials import LinearElastic, NeoHookean, NewtonianTait
from fempm.scene import Scene, run
from fempm.scenes import two_disks, vibrating_bar
from fempm.stepping import ExplicitSolver, Loads, SimulationError, StepOptions

comm = MPI.COMM_SELF
MESH = dm.create_unit_square(comm, 4, 4)
TWO = [[0.2, 0.2], [0.7, 0.7]]


def _space():
    return dolfinx.fem.functionspace(MESH, ("Lagrange", 1, (2,)))


def _solver(material=None, n=4, loads=None, compiled=None):
    p = fempm.create_particles(MESH, n, density=1.0) if n else fempm.Particles(MESH, np.zeros((0, 2)), 1.0, 1.0)
    s = ExplicitSolver(_space(), p, [material or NeoHookean(10.0, 0.3)], loads=loads or Loads(), options=StepOptions())
    if compiled is not None:
        s.compiled = compiled
    return s


@dataclasses.dataclass(frozen=True)
class Dust(LinearElastic):
    """A law with wave speed 0."""

    def wave_speed(self, F, rho):
        return np.zeros(len(F))


@dataclasses.dataclass(frozen=True)
class Flat(LinearElastic):
    """A law whose stress has the wrong shape."""

    def stress(self, F, L, sigma, dt, rho):
        return np.zeros((len(F), 3, 3))

    def wave_speed(self, F, rho):
        return np.ones(len(F))


def _with_field(name, value, before_first_step=True):
    """A solver whose particles' ``fields[name]`` is set to ``value(n)`` before its first step
    or between two steps."""
    p = fempm.create_particles(MESH, 4, density=1.0)
    s = ExplicitSolver(_space(), p, [NeoHookean(10.0, 0.3)]) if not before_first_step else None
    if s is not None:
        s.step()
    p.fields[name] = value(len(p))
    (s or ExplicitSolver(_space(), p, [NeoHookean(10.0, 0.3)])).step()


def _msh(folder, content: bytes):
    (folder / "empty.msh").write_bytes(content)
    fempm.meshes.read_msh(folder / "empty.msh", comm)


def _other_mesh():
    other = dm.create_unit_square(comm, 4, 4)
    ExplicitSolver(dolfinx.fem.functionspace(other, ("Lagrange", 1, (2,))),
                   fempm.create_particles(MESH, 4, density=1.0), [NeoHookean(10.0, 0.3)]).step()


def _absent_rigid_group():
    from fempm.stepping.contact import Contact

    p = fempm.create_particles(MESH, 4, density=1.0)
    p.fields["group"] = (p.x[:, 1] > 0.5).astype(np.int32)
    ExplicitSolver(_space(), p, [NeoHookean(10.0, 0.3)], contact=Contact(field="group", rigid=(7,))).step()


def _wrong_body(compiled):
    s = _solver(compiled=compiled)
    s.particles.fields["body"][:] = 1  # one material only
    s.step()


def _fast(tmp_path):
    scene = vibrating_bar(cells=4, t_end=1.0, comm=comm)
    scene.particles.fields["v"][:] = 1e200
    with np.errstate(over="ignore"):  # the kinetic energy overflows
        run(scene, tmp_path, progress=False)


def _inverted():
    s = _solver()
    s.particles.fields["F"][:, 0, :] *= -1.0
    s.step()


def _nan_velocity():
    s = _solver()
    s.particles.fields["v"][0, 0] = np.nan
    s.step()


def _too_large_dt():
    s = _solver()
    s.step(10 * s.stable_dt())


def _earlier_run(tmp_path):
    run(vibrating_bar(cells=4, t_end=0.2, comm=comm), tmp_path, progress=False)
    run(vibrating_bar(cells=4, t_end=0.2, comm=comm), tmp_path, progress=False, overwrite=False)


CASES = [  # (name, action (given a temporary folder), error class, message)
    ("E NaN", lambda _: NeoHookean(float("nan"), 0.3), ValueError, "needs E > 0"),
    ("E inf", lambda _: LinearElastic(float("inf"), 0.3), ValueError, "needs E > 0"),
    ("nu NaN", lambda _: NeoHookean(1.0, float("nan")), ValueError, "-1 < nu < 0.5"),
    ("nu 0.5", lambda _: NeoHookean(1.0, 0.5), ValueError, "-1 < nu < 0.5"),
    ("Tait kappa < 0", lambda _: NewtonianTait(rho0=1.0, kappa=-5.0), ValueError, "kappa > 0"),
    ("Tait rho0 = 0", lambda _: NewtonianTait(rho0=0.0), ValueError, "rho0 > 0"),
    ("Tait gamma NaN", lambda _: NewtonianTait(rho0=1.0, gamma=float("nan")), ValueError, "gamma > 1"),
    ("Tait viscosity < 0", lambda _: NewtonianTait(rho0=1.0, viscosity=-1.0), ValueError, "viscosity >= 0"),
    ("slip normal 0", lambda _: slip(_space(), lambda x: x[0] < 1e-9, (0.0, 0.0)), ValueError,
     "slip needs a finite, non-zero normal with 2 components"),
    ("slip normal NaN", lambda _: slip(_space(), lambda x: x[0] < 1e-9, (np.nan, 1.0)), ValueError,
     "slip needs a finite, non-zero normal"),
    ("slip normal 3D", lambda _: slip(_space(), lambda x: x[0] < 1e-9, (1.0, 0.0, 0.0)), ValueError,
     "with 2 components"),
    ("prescribed velocity all free", lambda _: prescribed(_space(), lambda x: x[1] > 1 - 1e-9, (np.nan, np.nan)),
     ValueError, "prescribed needs a velocity with 2 components, finite or NaN"),
    ("friction coefficient < 0", lambda _: friction(_space(), lambda x: x[1] < 1e-9, (0.0, -1.0), -0.2), ValueError,
     "mu >= 0"),
    ("mass inf", lambda _: fempm.Particles(MESH, TWO, np.inf, 1.0), ValueError, "non-positive or non-finite mass"),
    ("volume inf", lambda _: fempm.Particles(MESH, TWO, 1.0, np.inf), ValueError, "non-finite volume"),
    ("mass NaN", lambda _: fempm.Particles(MESH, TWO, np.nan, 1.0), ValueError, "non-finite mass"),
    ("mass 0", lambda _: fempm.Particles(MESH, TWO, 0.0, 1.0), ValueError, "non-positive or non-finite mass"),
    ("mass of wrong length", lambda _: fempm.Particles(MESH, TWO, [1.0, 2.0, 3.0], 1.0), ValueError,
     r"mass has shape \(3,\) for 2 particles"),
    ("volume of wrong shape", lambda _: fempm.Particles(MESH, TWO, 1.0, np.ones((2, 2))), ValueError,
     r"volume has shape \(2, 2\) for 2 particles"),
    ("position NaN", lambda _: fempm.Particles(MESH, [[np.nan, 0.5]], 1.0, 1.0), ValueError,
     "particle position.* not finite"),
    ("position in 3D", lambda _: fempm.Particles(MESH, [[0.5, 0.5, 0.2]], 1.0, 1.0), ValueError,
     "positions must have 2 coordinates"),
    ("position outside", lambda _: fempm.Particles(MESH, [[1.5, 0.5]], 1.0, 1.0), OutsideMeshError, "outside"),
    ("field of wrong length", lambda _: fempm.Particles(MESH, TWO, 1.0, 1.0, fields={"v": np.zeros((3, 2))}),
     ValueError, "field 'v' has 3 rows for 2 particles"),
    ("ids repeated", lambda _: fempm.Particles(MESH, TWO, 1.0, 1.0, ids=[7, 7]), ValueError,
     r"particle ids must be unique over all ranks; repeated: \[7\]"),
    ("ids not integers", lambda _: fempm.Particles(MESH, TWO, 1.0, 1.0, ids=[0.5, 1.5]), ValueError,
     "ids must be 2 integers"),
    ("dt < 0", lambda _: _solver().step(-1e-3), ValueError, "must be a positive, finite time step"),
    ("dt = 0", lambda _: _solver().step(0.0), ValueError, "must be a positive, finite time step"),
    ("dt NaN", lambda _: _solver().step(np.nan), ValueError, "must be a positive, finite time step"),
    ("dt inf", lambda _: _solver().step(np.inf), ValueError, "must be a positive, finite time step"),
    ("dt_max = 0", lambda _: _solver().step(dt_max=0.0), ValueError, "dt_max=0.0 must be positive"),
    ("no particles", lambda _: _solver(n=0).step(), ValueError, "there are no particles"),
    ("wave speed 0 at rest", lambda _: _solver(Dust(1.0, 0.0)).step(), ValueError, "no stable time step"),
    ("body without material, generic step", lambda _: _wrong_body(False), ValueError,
     r"body index outside the 1 material\(s\)"),
    ("body without material, compiled step", lambda _: _wrong_body(True), ValueError,
     r"body index outside the 1 material\(s\)"),
    ("body force of wrong shape", lambda _: _solver(loads=Loads(body_force=(0.0, 0.0, -9.8))).step(), ValueError,
     r"the body force has shape \(3,\), expected \(2,\)"),
    ("body force function of wrong shape",
     lambda _: _solver(loads=Loads(body_force=lambda x, t: np.zeros((1, 2)))).step(), ValueError,
     "the body force returned shape"),
    ("traction of wrong shape", lambda _: _solver(loads=Loads(traction=lambda t: np.zeros(2))).step(), ValueError,
     "the traction returned shape"),
    ("stress of wrong shape", lambda _: _solver(Flat(1.0, 0.3)).step(), ValueError,
     r"Flat.stress returned an array of shape \(\d+, 3, 3\)"),
    ("dt above the stability limit", lambda _: _too_large_dt(), SimulationError, "exceeds the stability limit"),
    ("inverted F", lambda _: _inverted(), SimulationError, r"inverted deformation J <= 0 at particle\(s\)"),
    ("NaN velocity", lambda _: _nan_velocity(), SimulationError, "non-finite state"),
    ("v = 1e200", _fast, SimulationError, r"non-finite state at particle"),  # v . v overflows: the kinetic energy
    ("scheme", lambda _: StepOptions(scheme="USX"), ValueError, "unknown option scheme='USX'"),
    ("mass option", lambda _: StepOptions(mass="diag"), ValueError, "unknown option mass='diag'"),
    ("CFL > 1", lambda _: StepOptions(cfl=1.5), ValueError, "CFL number above 1"),
    ("flip > 1", lambda _: StepOptions(flip=1.5), ValueError, r"flip=1.5 must lie in \[0, 1\]"),
    ("damping < 0", lambda _: StepOptions(damping=-1.0), ValueError, "damping=-1.0 must be >= 0"),
    ("J bounds", lambda _: Health(j_min=2.0), ValueError, "J bounds"),
    ("dt floor", lambda _: Health(dt_floor=1.0), ValueError, r"dt_floor=1.0 must lie in \[0, 1\)"),
    ("t_end = 0", lambda _: vibrating_bar(cells=4, t_end=0.0, comm=comm), ValueError, "must be a positive, finite time"),
    ("t_end < 0", lambda _: vibrating_bar(cells=4, t_end=-1.0, comm=comm), ValueError, "positive, finite time"),
    ("t_end NaN", lambda _: vibrating_bar(cells=4, t_end=np.nan, comm=comm), ValueError, "positive, finite time"),
    ("t_end inf", lambda _: vibrating_bar(cells=4, t_end=np.inf, comm=comm), ValueError, "positive, finite time"),
    ("cells = 0", lambda _: two_disks(cells=0, comm=comm), ValueError, "cells=0 must be a positive integer"),
    ("ppc 2.5", lambda _: vibrating_bar(ppc=2.5, comm=comm), ValueError, "ppc=2.5 must be a positive integer"),
    ("dim 3", lambda _: vibrating_bar(dim=3, comm=comm), ValueError, "dim=3 must be 1 or 2"),
    ("frames < 0", lambda _: Scene("s", MESH, fempm.Particles(MESH, TWO, 1.0, 1.0), [], t_end=1.0, frames=-1),
     ValueError, "frames=-1 must be a non-negative integer"),
    ("checkpoint_every 0", lambda d: run(vibrating_bar(cells=4, comm=comm), d, checkpoint_every=0), ValueError,
     "checkpoint_every=0 must be a positive number of steps"),
    ("checkpoint without a folder", lambda _: run(vibrating_bar(cells=4, comm=comm), checkpoint_every=5), ValueError,
     "checkpoints need an output folder"),
    ("resume without a checkpoint", lambda d: run(vibrating_bar(cells=4, comm=comm), d, resume=True),
     CheckpointError, "no checkpoint in"),
    ("an earlier run, no overwrite", _earlier_run, OutputFolderError, "holds the outputs of an earlier run"),
    ("particles of another mesh", lambda _: _other_mesh(), ValueError, "particles were made on another mesh"),
    ("v with 3 columns in 2D", lambda _: _with_field("v", lambda n: np.zeros((n, 3))), ValueError,
     r"particle fields\['v'\] has shape \(\d+, 3\), expected \(\d+, 2\)"),
    ("v with a row too few", lambda _: _with_field("v", lambda n: np.zeros((n - 1, 2))), ValueError,
     r"particle fields\['v'\] has shape"),
    ("sigma replaced between steps", lambda _: _with_field("sigma", lambda n: np.zeros((n + 2, 2, 2)), False),
     ValueError, r"particle fields\['sigma'\] has shape"),
    ("a user field of the wrong length", lambda _: _with_field("tag", lambda n: np.zeros(n + 1)), ValueError,
     r"particle fields\['tag'\] has shape \(\d+,\), expected"),
    ("mass_cutoff < 0", lambda _: StepOptions(mass_cutoff=-1), ValueError, r"mass_cutoff=-1 must lie in \[0, 1\)"),
    ("lump_below 1", lambda _: StepOptions(lump_below=1.0), ValueError, r"lump_below=1.0 must lie in \[0, 1\)"),
    ("cfl a string", lambda _: StepOptions(cfl="0.4"), TypeError, "StepOptions: cfl='0.4' must be a number"),
    ("yield stress a string", lambda _: fempm.materials.VonMises(1.0, 0.3, yield_stress="100"), TypeError,
     "VonMises: yield_stress='100' must be a number"),
    ("E a boolean", lambda _: LinearElastic(True, 0.3), TypeError, "LinearElastic: E=True must be a number"),
    ("kappa a string", lambda _: NewtonianTait(1000.0, kappa="2e4"), TypeError, "NewtonianTait: kappa='2e4'"),
    ("absent rigid group", lambda _: _absent_rigid_group(), ValueError, r"rigid group\(s\) \[7\] hold no particle"),
    ("disks friction without contact", lambda _: two_disks(friction=0.5, comm=comm), ValueError,
     "friction=0.5 needs contact=True"),
    ("impact friction without contact", lambda _: fempm.scenes.disk_impact(contact=False, friction=0.5, comm=comm),
     ValueError, "friction=0.5 needs contact=True"),
    ("disks that overlap", lambda _: two_disks(radius=0.9, comm=comm), ValueError, r"radius=0.9 must lie in \(0, 0.2\]"),
    ("cook spacing < 0", lambda _: fempm.scenes.cook_membrane(spacing=-1.0, comm=comm), ValueError,
     "spacing=-1.0 must be a positive length"),
    ("cantilever g NaN", lambda _: fempm.scenes.cantilever(g=np.nan, comm=comm), ValueError,
     "g=nan must be a finite number"),
    ("unknown variant", lambda _: fempm.scenes.cook_membrane(variant="foo", comm=comm), ValueError,
     "unknown option variant='foo'"),
    ("lumped P2 Lagrange", lambda _: fempm.scenes.cantilever(degree=2, comm=comm), ValueError,
     "mass='lumped' needs a non-negative basis"),
    ("P2 consistent, too few particles", lambda _: fempm.scenes.cantilever(degree=2, mass="consistent", ppc=4,
                                                                          comm=comm),
     ValueError, r"ppc=4 particles per cell cannot determine the consistent mass of degree 2 \(9 dofs"),
    ("P2 consistent, too coarse a lattice", lambda _: fempm.scenes.cook_membrane(degree=2, mass="consistent",
                                                                               spacing=1.0, comm=comm),
     ValueError, "spacing=1.0 leaves 1 particle.* needs 6 in every one"),
    ("a cells callable of rows", lambda _: fempm.create_particles(dm.create_unit_square(comm, 4, 4), 4,
                                                                 cells=lambda x: x[:, 0] < 0.5),
     ValueError, r"cells\(x\) must return one boolean per cell: x holds the \d+ cell midpoints as columns"),
    ("an empty .msh", lambda d: _msh(d, b""), MeshFileError, r"empty.msh' is not a readable gmsh mesh: it holds no cells"),
    ("a corrupt .msh", lambda d: _msh(d, (fempm.meshes.MESHES / "unit_square_tri.msh").read_bytes()[:400]), MeshFileError,
     r"empty.msh' is not a readable gmsh mesh \(gmsh: Could not read"),
    ("a text file as .msh", lambda d: _msh(d, b"Unknown variable world\n"), MeshFileError,
     r"empty.msh' is not a readable gmsh mesh"),
    ("a missing .msh", lambda d: fempm.meshes.read_msh(d / "nowhere.msh", comm), MeshFileError,
     r"mesh file '.*nowhere.msh' does not exist"),
    ("frames above the output limit", lambda d: run(fempm.scenes.column_collapse(aspect=50.0, cells=8, comm=comm), d,
                                                    progress=False), OutputSizeError,
     r"would write about 3.\d+ GB of frames \(21 frames .* give fewer frames \(--frames\), or --force"),
    ("ppc not a square", lambda _: fempm.scenes.dam_break(ppc=2, comm=comm), ValueError,
     r"ppc=2 particles per cell must be a square for the per-cell lattice in 2D \(1, 4, 9"),
]


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial inputs")
@pytest.mark.parametrize("name, action, error, message", CASES, ids=[c[0] for c in CASES])
def test_bad_input(name, action, error, message, tmp_path):
    with pytest.raises(error, match=message):
        action(tmp_path)


def test_the_table_covers_enough_inputs():
    assert len(CASES) >= 40 and len({c[0] for c in CASES}) == len(CASES)


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial inputs")
def test_a_bound_given_to_a_law_without_wave_speed_makes_a_step():
    assert _solver(Dust(1.0, 0.0)).step(dt_max=1e-3) == 1e-3


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial inputs")
def test_particle_domains_by_name_everywhere():
    """fempm.project and Projector take the domain names StepOptions takes (before, "gimp"
    failed with "'str' object has no attribute 'samples'")."""
    V = dolfinx.fem.functionspace(MESH, ("Lagrange", 1))
    p = fempm.create_particles(MESH, 4, density=1.0)
    from fempm.transfer.domains import make_domain

    for name in ("point", "gimp", "ugimp", "cpgimp", "cpdi1"):
        u = fempm.project(V, p, lambda x: 1.0 + 2.0 * x[0], domain=name, mass="consistent")
        ref = fempm.project(V, p, lambda x: 1.0 + 2.0 * x[0], domain=make_domain(name), mass="consistent")
        assert np.array_equal(u.x.array, ref.x.array), name
        assert np.allclose(u.x.array, 1.0 + 2.0 * V.tabulate_dof_coordinates()[:, 0], atol=1e-2), name


def test_the_readme_names_import():
    from fempm.scenes import manufactured_scene  # noqa: F401  (as the README writes it)


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial inputs")
def test_p2_consistent_scenes_seed_enough_particles_by_default():
    """Cantilever and Cook's membrane with P2 consistent mass start without a singular mass
    (before: SingularMassError at the start): 9 particles per quadrilateral, and a Cook lattice
    refined until every triangle holds 6."""
    from fempm.scene import emptiest_cell

    c = fempm.scenes.cantilever(degree=2, mass="consistent", t_end=2e-4, frames=1, comm=comm)
    assert c.params["ppc"] == 9
    assert run(c, None, progress=False)["status"] == "completed"
    k = fempm.scenes.cook_membrane(degree=2, mass="consistent", t_end=0.05, frames=1, comm=comm)
    assert emptiest_cell(k.particles) >= 6
    assert run(k, None, progress=False)["status"] == "completed"
