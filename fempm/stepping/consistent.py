r"""The consistent grid mass of the compiled passes (:class:`ConsistentNodalMass`).

The passes of :class:`fempm.stepping.lumped.PointGrid` (P2G, G2P with the kinematics and the
laws, motion and relocation) with the grid update of the consistent mass, whose reference is
:class:`~fempm.stepping.grid.SingleFieldGrid` with ``mass="consistent"``:

.. math::
    \sum_j m_{ij} v_j = (m v)_i, \qquad \sum_j m_{ij} a_j = f_i, \qquad
    m_{ij} = \sum_p M_p N_i(x_p) N_j(x_p),

on the supported dofs, rows and columns of lightly supported dofs lumped (``lump_below``),
slip components solved on their own dofs, the acceleration 0 where the lumped mass is below
``mass_cutoff``, and the stable step times :math:`\sqrt{0.8\,\lambda_{min}(M_L^{-1} M_C)}`.
One more particle pass (:func:`fempm.kernels.consistent.cell_mass`) sums :math:`m_{ij}` per
cell; the PETSc matrices, their sparsity and their KSPs are kept for the run
(:class:`fempm.stepping.mass_systems.ConsistentSystems`), the velocity solve starts from the last grid
velocity and the acceleration solve from the last acceleration.

With a given ``dt`` the stable-step estimate (30 CG steps) only checks that ``dt`` is stable,
and is refreshed every :data:`RATIO_EVERY` steps and whenever the sparsity changes; with the
stable step (``dt=None``) it is refreshed every step.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from fempm.kernels import consistent as kc
from fempm.kernels import consistent_domains as kcd
from fempm.kernels.shape import space_of
from fempm.stepping.mass_sparsity import cells_around
from fempm.stepping.mass_systems import ConsistentSystems
from fempm.stepping.nodal import NodalLayout, NodalMass, sum_ghosts
from fempm.transfer.domains import GIMP
from fempm.transfer.mass_models import MASS_RATIO_ITERATIONS

__all__ = ["RATIO_EVERY", "WIDENINGS", "WIDE_SHARE", "ConsistentNodalMass", "DomainConsistentMass"]

#: steps between two refreshes of the stable-step estimate when ``dt`` is given
RATIO_EVERY = 20
#: the share of the cells holding particles beyond which every cell keeps its star dofs by star
#: dofs (:meth:`DomainConsistentMass.widen`)
WIDE_SHARE = 0.25
#: the widening of a run after which every cell keeps its star dofs by star dofs
WIDENINGS = 2


class ConsistentNodalMass(NodalMass):
    """The consistent grid mass of a :class:`~fempm.stepping.lumped.PointGrid` (see the module)."""

    fusable = False  # the grid update solves with the consistent matrix

    def __init__(self, layout: NodalLayout):
        super().__init__(layout)
        state, opts = layout.state, layout.options
        # no row lumped on a basis with negative values (P2 Lagrange): it could make the matrix
        # indefinite (as fempm.transfer.Projector)
        nonnegative = space_of(layout.cell) != (2, False)
        element_dofs, layer_dofs = self.element_dofs()
        self.systems = ConsistentSystems(state.V, element_dofs, layout.free, layout.conditions.fixed_mask(),
                                         prefix=opts.petsc_options_prefix,
                                         lump_below=opts.lump_below if nonnegative else 0.0,
                                         always_lumped=layout.conditions.friction_dofs if nonnegative else None,
                                         nonnegative=nonnegative, layer_dofs=layer_dofs)
        self.cell_mass = kc.cell_mass(layout.cell)
        self.assembled = False  # this step's blocks summed already (assemble)
        self._ghosted = layout.nodal_array(layout.d)
        self._signed: tuple | None = None  # a kept nodal array: degree-2 Lagrange's signed lumped masses
        self._accel: npt.NDArray | None = None  # the last acceleration, the warm start of its solve
        self._spare: npt.NDArray | None = None  # the array of the acceleration before it
        self.ratio_age = RATIO_EVERY  # steps since the stable-step estimate
        self._ratio_key = -1
        #: the last estimate of :math:`\lambda_{min}(M_L^{-1} M_C)`
        self.ratio = 1.0
        self._always_lumped = self.systems.always_lumped  # the dofs lumped in any case

    def stable_factor(self, nodal, need: bool, top: float, masses: npt.NDArray | None = None,
                      lumped: npt.NDArray | None = None) -> float:
        """The mass pass and the matrices' values; :math:`\\sqrt{0.8\\,\\lambda_{min}}` (1 with
        lumped forces). ``masses``: the particle masses of the matrix in place of the particles'
        (one body's, zero for the others: multi-field contact, with ``nodal`` that body's P2G
        columns); ``lumped``: more dofs (owned + ghost) whose rows are lumped this step."""
        g = self.layout
        s = g.state
        p = s.particles
        sy = self.systems
        if lumped is not None:
            sy.always_lumped = lumped if self._always_lumped is None else self._always_lumped | lumped
        if not self.assembled:
            self.assemble(masses)
        self.assembled = False
        sy.update(sy.work_arrays(fill=False)[1], nodal[:, 0], p.num_global)
        if g.options.lumped_forces:
            return 1.0
        key = sy.rebuilds
        self.ratio_age += 1
        if need or key != self._ratio_key or self.ratio_age >= RATIO_EVERY:
            self.ratio = s.record.mass_ratio = sy.mass_ratio_min(s.V, MASS_RATIO_ITERATIONS)
            self._ratio_key, self.ratio_age = key, 0
        return g.options.mass_model.stable_factor(lambda: self.ratio)

    def element_dofs(self) -> tuple[npt.NDArray, npt.NDArray | None]:
        """The dofs of the matrix's blocks per cell and the dofmap of the layer around the
        occupied cells (None: the same): the cells' own dofs."""
        return self.layout.cell_dofs, None

    def mass_pass(self, masses: npt.NDArray, blocks, diagonal, count) -> tuple[int, int]:
        """The particle pass summing the blocks, the diagonal and the particles per cell
        (:func:`fempm.kernels.consistent.cell_mass`); returns (particles in cells without a
        block, particles the blocks cannot hold: none here)."""
        g = self.layout
        p = g.state.particles
        return self.cell_mass(p.cells, p.X, g.K, g.cell_dofs, masses, self.systems.pattern, blocks, diagonal,
                              count), 0

    def assemble(self, masses: npt.NDArray | None = None) -> int:
        """This step's blocks, diagonal (summed over ranks) and counts from the particles
        (``masses``: in place of theirs, one body's), the sparsity rebuilt where a particle is in
        a cell outside it; returns the number of particles, over all ranks, whose blocks the
        sparsity cannot hold (:meth:`mass_pass`; the step then goes elsewhere). Collective."""
        p = self.layout.state.particles
        sy = self.systems
        masses = p.mass if masses is None else masses
        while True:
            blocks, diagonal, count, dvec = sy.work_arrays()
            missing, outside = self.mass_pass(masses, blocks, diagonal, count)
            missing, outside = p.comm.allreduce(np.array([missing, outside]))
            if not missing:
                break
            sy.rebuild(p.cells[masses != 0.0])
        sum_ghosts(dvec[0])
        self.assembled = not outside
        return int(outside)

    def checkpoint_state(self) -> tuple[dict, dict[str, npt.NDArray]]:
        """This rank's state that a resumed run needs to repeat the next steps bit for bit: the
        warm start of the acceleration solve, the kept systems (:meth:`ConsistentSystems.state`)
        and the stable-step estimate's age and key."""
        arrays = {f"mass:{k}": v for k, v in self.systems.state().items()}
        arrays["ratio_key"] = np.array([self._ratio_key])
        arrays["ratio"] = np.array([self.ratio])
        if self._accel is not None:
            arrays["accel"] = self._accel
        return {"ratio_age": self.ratio_age}, arrays

    def restore_state(self, counters: dict, arrays: dict[str, npt.NDArray]) -> None:
        """The state of :meth:`checkpoint_state` (arrays from a run on as many ranks; an empty
        dict on another number of ranks: the next steps then agree to round-off). Collective."""
        if counters.get("ratio_age") is not None:
            self.ratio_age = int(counters["ratio_age"])
        self._accel = arrays.get("accel")
        if "ratio_key" in arrays:
            self._ratio_key = int(arrays["ratio_key"][0])
        if "ratio" in arrays:
            self.ratio = float(arrays["ratio"][0])
        self.systems.restore({k[5:]: v for k, v in arrays.items() if k.startswith("mass:")})

    def lumped(self, nodal: npt.NDArray) -> npt.NDArray:
        r"""The lumped masses :math:`\sum_p M_p N_{ip}`: the P2G mass column, or for a signed
        basis (degree-2 Lagrange, whose column holds :math:`\sum_p M_p |N_{ip}|`) :math:`M_C 1`,
        one more particle pass."""
        g = self.layout
        if space_of(g.cell) != (2, False):
            return nodal[:, 0]
        vec, out = self._signed = self._signed or g.nodal_array(1)
        out.fill(0.0)
        g.mass_apply(np.ones((g.num_dofs, 1)), np.zeros(0, dtype=np.bool_), out)
        sum_ghosts(vec)
        return out[:, 0]

    def _ghosts(self, u: npt.NDArray) -> npt.NDArray:
        """Owned values of ``u`` (dofs, d) to the ghosts (in place)."""
        vec, arr = self._ghosted
        if vec is not None:
            arr[:] = u
            vec.scatter_forward()
            u[:] = arr
        return u

    def velocity(self, mass, mom, cv: int, active_min: float, guess=None, centroids=None,
                 forces: int | None = None, start: npt.NDArray | None = None) -> npt.NDArray:
        g = self.layout  # (the exact projection leaves a lumped first solve's ``start`` out)
        v = np.zeros((g.num_dofs, g.d))
        self.systems.solve(mom, cv, v, guess)
        g.conditions.apply(v, centroids)
        return self._ghosts(v)

    def acceleration(self, mass, force, cf: int) -> npt.NDArray:
        """The accelerations of the nodal forces ``force[:, cf:cf+d]`` (owned + ghost dofs, d):
        the consistent solve from the last ones, or with ``lumped_forces`` the division by the
        lumped masses ``mass[:, 0]`` on the supported dofs."""
        g = self.layout
        sy = self.systems
        a = self._spare if self._spare is not None else np.zeros((g.num_dofs, g.d))
        if g.options.lumped_forces:
            m = mass[:, 0]
            a[sy.active] = force[sy.active, cf:cf + g.d] / m[sy.active, None]
        else:
            sy.solve(force, cf, a, self._accel)  # every owned entry of a written
            self._ghosts(a)
            self._accel, self._spare = a, self._accel  # the next warm start; the next output
        return a

    def advance(self, mass, force, cf: int, active_min: float, weak_max: float, dt: float, v_old: npt.NDArray,
                centroids=None) -> npt.NDArray:
        g = self.layout
        opts = g.options
        a = self.acceleration(mass, force, cf)
        v_new = np.empty_like(a)
        kc.advance(a, v_old, mass[:, 0], weak_max, float(dt), float(opts.damping), v_new)
        g.conditions.apply(v_new, centroids, dt)
        return self._ghosts(v_new)


class DomainConsistentMass(ConsistentNodalMass):
    r"""The consistent grid mass of particle domains (:class:`fempm.stepping.domain_grid.DomainGrid`):
    :math:`m_{ij} = \sum_p M_p \langle N_i \rangle_p \langle N_j \rangle_p`, the reference
    :func:`fempm.transfer.mapping.consistent_mass_matrix` on the averaged basis. The blocks are
    summed per cell over the dofs of its vertex star (:mod:`fempm.kernels.consistent_domains`),
    which hold every dof the samples of its particles reach; the kept systems, solves and
    stable-step estimate are those of :class:`ConsistentNodalMass`. A step with a sample beyond
    its particle's vertex star goes to the numpy grid (:meth:`prepare`)."""

    def __init__(self, layout: NodalLayout):
        self._star = None
        super().__init__(layout)
        #: Gauss or exact GIMP (the samples' kind, :func:`fempm.kernels.samples.kernels_for`)
        self.gimp = isinstance(layout.options.particle_domain, GIMP)
        self.widenings = 0  #: the sparsity's widenings so far (:meth:`widen`)

    def element_dofs(self) -> tuple[npt.NDArray, npt.NDArray | None]:
        """The dofs of each cell's vertex star and, for the layer, the dofmap."""
        g = self.layout
        if self._star is None:
            self._star = kcd.star_dofs(g.state.particles.sample_locator.vertex_star(), g.cell_dofs)
        return self._star, g.cell_dofs

    def mass_pass(self, masses: npt.NDArray, blocks, diagonal, count) -> tuple[int, int]:
        """The domains' pass (:func:`fempm.kernels.consistent_domains.domain_cell_mass`); the
        cells whose particles reached pairs of dofs the sparsity does not keep join its wide
        cells (:mod:`fempm.stepping.mass_sparsity`) and count as missing: the sparsity is rebuilt."""
        p = self.layout.state.particles
        samples = self.layout.samples()
        kernel = kcd.domain_cell_mass(self.layout.cell, self.gimp, samples.Fw.shape[0] > 0)
        sy = self.systems
        wide = np.zeros(len(sy.pattern_cells), dtype=np.bool_)
        missing, outside, widened = kernel(p.cells, samples, masses, self._star, sy.pattern, sy.slot, blocks, diagonal,
                                           count, wide)
        if widened:
            self.widen(sy.pattern_cells[wide])
        return missing + widened, outside

    def widen(self, cells: npt.NDArray[np.int32]) -> None:
        """The cells sharing a vertex with ``cells`` (whose particles reached pairs of dofs the
        sparsity does not keep) join the wide cells, which keep their star dofs by star dofs
        (:mod:`fempm.stepping.mass_sparsity`): particles leave a cell for its neighbours, and a
        domain wider than a cell here is likely so there. When the wide cells are more than
        :data:`WIDE_SHARE` of the cells with particles, or at the :data:`WIDENINGS` th widening
        of the run, every cell is wide (domains larger than the cells, as on tetrahedra split from
        cubes, reach new pairs every step, and a rebuild of the sparsity costs 10-20 steps)."""
        sy = self.systems
        self.widenings += 1
        wide = np.union1d(sy.wide, cells_around(sy.layer_dofs[: sy.num_cells], cells, sy.num_dofs))
        if (len(wide) > WIDE_SHARE * len(np.unique(self.layout.state.particles.cells))
                or self.widenings >= WIDENINGS):
            wide = np.arange(sy.num_cells)
        sy.wide = wide.astype(np.int32)

    def checkpoint_state(self) -> tuple[dict, dict[str, npt.NDArray]]:
        """:meth:`ConsistentNodalMass.checkpoint_state` and the widenings so far."""
        counters, arrays = super().checkpoint_state()
        return counters, {**arrays, "widenings": np.array([self.widenings])}  # (of this rank)

    def restore_state(self, counters: dict, arrays: dict[str, npt.NDArray]) -> None:
        super().restore_state(counters, arrays)
        if "widenings" in arrays:
            self.widenings = int(arrays["widenings"][0])

    def prepare(self) -> bool:
        """This step's blocks, before the grid takes the step: whether every particle's samples
        lie in its vertex star (else the numpy grid takes it). Collective."""
        return self.assemble() == 0
