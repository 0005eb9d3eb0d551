"""A scene is data (mesh, particles with a body index, materials, boundary conditions, loads,
transfer options, outputs), checked as it is made."""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import basix
import basix.ufl
import dolfinx.fem
import dolfinx.mesh
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.particles.particle_set import Particles
from fempm.stepping.contact import Contact
from fempm.stepping.health import Health
from fempm.stepping.loads import Loads
from fempm.stepping.options import StepOptions
from fempm.stepping.outside import outside_policy
from fempm.stepping.solver import ExplicitSolver
from fempm.timings import SETUP
from fempm.transfer.transfers import AFFINE_FIELD

__all__ = [
    "MAX_STEPS", "OUTPUTS", "VARIANTS", "Scene", "check_counts", "check_finite", "checked", "dofs_per_cell",
    "emptiest_cell",
]


def check_counts(**counts: int) -> None:
    """Scene builders' counts (cells, particles per cell, frames, ...) must be positive
    integers: a ValueError naming the first that is not."""
    for name, value in counts.items():
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{name}={value!r} must be a positive integer")


def check_finite(**values: float) -> None:
    """Scene builders' physical parameters must be finite real numbers: a ValueError naming the
    first that is not (NaN would otherwise fail deep inside the mesh set-up)."""
    for name, value in values.items():
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                or not np.isfinite(value):
            raise ValueError(f"{name}={value!r} must be a finite number")


def checked(positive: tuple[str, ...] = (), non_negative: tuple[str, ...] = ()):
    """A scene builder whose numeric parameters ``positive`` must be finite and > 0 (lengths,
    moduli, densities, times: a zero width divides by zero, a negative height is a mesh dolfinx
    refuses in its own words) and ``non_negative`` finite and >= 0 (friction coefficients,
    viscosities): a ValueError naming the first that is not, before anything is built. None
    (a parameter's "default from the others") passes."""
    def wrap(builder):
        signature = inspect.signature(builder)

        @functools.wraps(builder)
        def build(*args, **kwargs):
            bound = signature.bind(*args, **kwargs)
            bound.apply_defaults()
            for names, ok, what in ((positive, lambda v: v > 0, "> 0"), (non_negative, lambda v: v >= 0, ">= 0")):
                for name in names:
                    value = bound.arguments[name]
                    if value is None:
                        continue
                    check_finite(**{name: value})
                    if not ok(value):
                        raise ValueError(f"{name}={value!r} must be {what}")
            return builder(*args, **kwargs)

        return build

    return wrap


def dofs_per_cell(cell_name: str, degree: int) -> int:
    """The dofs of a scalar Lagrange element of ``degree`` on a cell: the fewest particles in a
    cell that can determine its consistent mass block."""
    k = degree
    return {"interval": k + 1, "triangle": (k + 1) * (k + 2) // 2, "quadrilateral": (k + 1) ** 2,
            "tetrahedron": (k + 1) * (k + 2) * (k + 3) // 6, "hexahedron": (k + 1) ** 3}[cell_name]


def emptiest_cell(particles: Particles) -> int:
    """The fewest particles in an owned cell of the particles' mesh, over all ranks (collective)."""
    num = particles.mesh.topology.index_map(particles.mesh.topology.dim).size_local
    counts = np.bincount(particles.cells[particles.cells < num], minlength=num)
    return particles.comm.allreduce(int(counts.min(initial=np.iinfo(np.int64).max)), op=MPI.MIN)


#: the Lagrange variants a scene's space can take (basix's names, :attr:`Scene.variant`)
VARIANTS = tuple(v.name for v in basix.LagrangeVariant if v.name != "unset")

#: the frames a scene can ask for (:attr:`Scene.outputs`)
OUTPUTS = ("particles", "grid_velocity", "grid_stress")

#: more steps than this to the end time is a collapsed time step (a run that would not end)
MAX_STEPS = 1e9

@dataclass
class Scene:
    """Everything a run needs (:func:`fempm.scene.run`).

    Args:
        name: The scene's name (its output folder's default, its summary's ``scene``).
        mesh: The background mesh.
        particles: The particles, with their fields.
        materials: The laws, one per value of ``fields["body"]``.
        t_end: The end time.
        bcs: Builds the grid conditions from the velocity space, ``V -> [condition, ...]``.
        loads: Body forces and tractions.
        options: The step's options.
        degree: The velocity space's degree.
        frames: The number of particle and grid frames over ``[0, t_end]``.
        params: The scene's parameters, written to the summary and the checkpoint.
        dt: A fixed time step (the last step shortened to end at ``t_end``; a step above the
            stability limit is an error); None takes the CFL step every step.
        variant: The Lagrange variant of the velocity space (e.g. ``"bernstein"``), default
            DOLFINx's.
        health: The limits that stop an unhealthy run (:class:`fempm.stepping.health.Health`:
            energy growth beyond the work of the loads, J bounds, time-step floor).
        outputs: The frames a run with an output folder writes, of :data:`OUTPUTS` (the
            energies and the summary always); what is not asked for is not computed.
        results: The scene's own measures of the final state, ``results(scene, solver) ->
            dict`` (collective), added to the summary.
        contact: One velocity field per particle group with frictional contact
            (:class:`fempm.stepping.contact.Contact`); None: one field.
        outside: ``"raise"`` (a particle leaving the mesh ends the run) or ``"remove"`` (it is
            dropped, what it takes accounted: :mod:`fempm.stepping.outside`).
        watch: Called with the solver after every step (collective), for the scene's own
            histories (a continued run calls it from the checkpoint on).
        colliders: Rigid obstacles given as shapes (:class:`fempm.colliders.Collider`); their
            forces go to ``energies.csv`` (``collider_force_<k>_x``, ...) and ``summary.json``
            (``colliders``).
        velocity_gradient: The particles' initial velocity gradient, (d, d) or (n, d, d), from
            which APIC and TPIC start their affine matrices
            (:meth:`fempm.stepping.Solver.set_velocity_gradient`; None: from 0); a resumed run
            keeps its checkpoint's.
        timings: The seconds its set-up took on this rank (``mesh_s``, ``particles_s``): by
            default what :data:`fempm.timings.SETUP` gathered since the previous scene was made
            (the run's summary reports them, :mod:`fempm.timings`).
    """

    name: str
    mesh: dolfinx.mesh.Mesh
    particles: Particles
    materials: Sequence
    t_end: float
    bcs: Callable[[dolfinx.fem.FunctionSpace], Sequence] | None = None
    loads: Loads = field(default_factory=Loads)
    options: StepOptions = field(default_factory=StepOptions)
    degree: int = 1
    frames: int = 20
    params: dict = field(default_factory=dict)
    dt: float | None = None
    variant: str | None = None
    health: Health = field(default_factory=Health)
    outputs: tuple[str, ...] = OUTPUTS
    results: Callable[[Scene, ExplicitSolver], dict] | None = None
    contact: Contact | None = None
    watch: Callable[[ExplicitSolver], None] | None = None
    outside: str = "raise"
    colliders: Sequence = ()
    velocity_gradient: npt.ArrayLike | None = None
    timings: dict[str, float] = field(default_factory=SETUP.take)

    def __post_init__(self):
        outside_policy(self.outside)
        unknown = set(self.outputs) - set(OUTPUTS)
        if unknown:
            raise ValueError(f"unknown output(s) {sorted(unknown)}; expected some of {OUTPUTS}")
        if not (0.0 < self.t_end < np.inf):
            raise ValueError(f"t_end={self.t_end} must be a positive, finite time")
        if isinstance(self.frames, bool) or not isinstance(self.frames, (int, np.integer)) or self.frames < 0:
            raise ValueError(f"frames={self.frames!r} must be a non-negative integer")
        if self.dt is not None and not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt={self.dt} must be a positive number (or None for the CFL step)")
        check_counts(degree=self.degree)
        if self.variant is not None and self.variant not in VARIANTS:
            raise ValueError(f"unknown option variant={self.variant!r}; expected one of {', '.join(VARIANTS)}")
        if self.degree > 1 and self.variant != "bernstein" and not self.options.mass_model.matrix:
            raise ValueError(f"mass={self.options.mass!r} needs a non-negative basis (degree 1 or variant='bernstein'): "
                             f"the vertex functions of degree-{self.degree} Lagrange integrate to zero or less, so their "
                             "lumped masses vanish; use mass='consistent' or variant='bernstein'")

    def space(self) -> dolfinx.fem.FunctionSpace:
        """The vector Lagrange velocity space of the scene's degree (and variant)."""
        d = self.mesh.geometry.dim
        if self.variant is None:
            return dolfinx.fem.functionspace(self.mesh, ("Lagrange", self.degree, (d,)))
        variant = getattr(basix.LagrangeVariant, self.variant)
        return dolfinx.fem.functionspace(
            self.mesh, basix.ufl.element("Lagrange", self.mesh.basix_cell(), self.degree, variant, shape=(d,)))

    def solver(self) -> ExplicitSolver:
        V = self.space()
        bcs = list(self.bcs(V)) if self.bcs is not None else []
        solver = ExplicitSolver(V, self.particles, self.materials, bcs=bcs, loads=self.loads, options=self.options,
                                contact=self.contact, outside=self.outside, colliders=self.colliders)
        if self.velocity_gradient is not None and AFFINE_FIELD not in self.particles.fields:  # (not a resumed run's)
            solver.set_velocity_gradient(self.velocity_gradient)
        return solver
