r"""The compiled passes of particle domains given by sample points (:class:`DomainGrid`).

The stages and checks of :class:`fempm.stepping.lumped.PointGrid` with the domain-averaged
basis of :mod:`fempm.kernels.samples` in place of the point basis: CPDI1 (the corners of
:math:`x_p + F_p \operatorname{diag}(\ell_p) [-1, 1]^d`, made in a compiled pass), CPDI2 (the
tracked corners, moved with the grid velocity at them, their weights made and the corners
located in the moving pass on triangles and quadrilaterals, in passes after it on the other cells) and GIMP with a
Gauss rule (``gimp_order``), on degree-1 cells (affine or multilinear); exact GIMP
(uGIMP, cpGIMP) on simplices and axis-aligned boxes, the pieces of each box in the cells it
meets as samples (:mod:`fempm.kernels.boxes`); lumped mass or FMPM(k), whose :math:`M_C y`
takes the averaged basis. Each step locates the
samples in the particle's cell or its vertex star (owned and ghost cells) in one compiled pass;
the few it does not find are located through the DOLFINx tree, and on one rank samples beyond
the mesh are treated as :class:`~fempm.transfer.basis.ParticleBasis` treats them (CPDI corners
at the closest point of the mesh, Gauss points dropped and the weights renormalised). A step
with a sample on no local cell on some rank (a domain reaching over the partition beyond the
ghost cells) is handed to the numpy :class:`~fempm.stepping.grid.SingleFieldGrid`, the
reference, which exchanges the samples between ranks. CPDI2 keeps the corner weights (and in 2D the cells) of the
corners a step moved for the next step (the same array in ``fields["corners"]``: corners
changed between steps are given as a new array, as the moving step does).
"""

from __future__ import annotations

import dolfinx.la
import numpy as np
import numpy.typing as npt

from fempm.kernels import samples as ks
from fempm.kernels.boxes import box_samples
from fempm.kernels.bundles import (
    NO_GROUPS,
    Basis,
    Corners,
    Forces,
    GridStep,
    Groups,
    Moves,
    Outputs,
    Samples,
    Stable,
    State,
)
from fempm.kernels.cpdi1 import cpdi1_samples, locate_corners
from fempm.kernels.sample_location import at_samples, locate_samples
from fempm.kernels.shape import CELLS, space_of
from fempm.particles.corners import corner_signs, domain_geometry
from fempm.stepping.grid import Grid, SingleFieldGrid
from fempm.stepping.lumped import PointGrid
from fempm.stepping.spaces import compiled_space, space_refusal
from fempm.stepping.state import StepState
from fempm.transfer.domains import CPDI1, CPDI2, GIMP, half_widths
from fempm.stepping.consistent import DomainConsistentMass
from fempm.stepping.lumped_mass import NODAL_MASSES
from fempm.transfer.mass_models import FMPM, Consistent, Lumped

__all__ = ["DomainGrid", "frontier_cells"]


def frontier_cells(locator) -> npt.NDArray[np.bool_]:
    """Per local cell of ``locator`` (owned and ghost), whether one of its vertices is shared
    with another rank (a ghost vertex, or an owned one another rank holds as a ghost): the
    cells around a vertex that no other rank shares are all this rank's own. Collective."""
    c2v = locator.vertex_star()[0]
    imap = locator.mesh.topology.index_map(0)
    if locator.mesh.comm.size == 1:
        return np.zeros(len(c2v), dtype=np.bool_)
    held = dolfinx.la.vector(imap, 1)
    held.array[:] = 0.0
    held.array[imap.size_local:] = 1.0
    held.scatter_reverse(dolfinx.la.InsertMode.add)  # owned vertices that another rank holds
    shared = held.array > 0.0
    shared[imap.size_local:] = True
    return np.ascontiguousarray(shared[c2v].any(axis=1))


class DomainGrid(PointGrid):
    """:class:`~fempm.stepping.lumped.PointGrid` with particle domains of sample points (see the
    module)."""

    takes = ("CPDI1, CPDI2 or GIMP domains (exact GIMP on simplices and axis-aligned boxes) with lumped, consistent or FMPM mass "
             "on degree 1 of the compiled passes, no wall that checks contact by position")

    #: the velocity transfers its passes take
    transfers = ("flip", "pic", "xpic")
    #: the grid mass of each mass model: the consistent one over the averaged basis
    nodal_masses = {**NODAL_MASSES, Consistent: DomainConsistentMass}

    @classmethod
    def refusal(cls, state: StepState) -> str | None:
        """Why ``state``'s domain, mass, conditions, space and mesh do not take this grid (None
        where they do)."""
        dom = state.options.particle_domain
        cell = compiled_space(state)
        if cell is None:
            return space_refusal(state)
        if space_of(cell) != (1, False):
            return "the particle domains' compiled passes take degree 1 (P1 on affine or multilinear cells)"
        if type(state.options.mass_model) not in (Lumped, FMPM, Consistent):
            return f"mass {state.options.mass_model.label} with particle domains: lumped, consistent or FMPM"
        if state.conditions.needs_positions:
            return "a wall or collider that checks contact by position takes point particles"
        if state.options.velocity_transfer.name not in cls.transfers:
            return f"transfer {state.options.velocity_transfer.name}: {', '.join(cls.transfers)}"
        # these types themselves: a subclass may make or move its samples otherwise
        if type(dom) is GIMP and dom.exact:  # pieces averaged at their centroids: simplices and axis-aligned boxes
            geo = state.particles.locator.geometry
            if not (cell in ("interval", "triangle", "tetrahedron")
                    or (cell in ("quadrilateral", "hexahedron") and geo.axis_aligned)):
                return "exact GIMP takes simplices and axis-aligned boxes (a Gauss-rule GIMP takes any cell)"
            return None
        if type(dom) not in (CPDI1, CPDI2, GIMP):
            return f"particle domain {dom.name}: CPDI1, CPDI2 or GIMP"
        return None

    def __init__(self, state: StepState):
        super().__init__(state)
        dom = self.options.particle_domain
        self.cpdi1 = isinstance(dom, CPDI1)
        self.exact = isinstance(dom, GIMP) and dom.exact
        self.passes = ks.kernels_for(self.cell, grad_from_values=isinstance(dom, GIMP))
        self.no_gradient_weights = np.zeros((1, 1, self.d))  # GIMP's and CPDI1's (not read)
        self.no_weights = np.zeros((0, 2**self.d))  # CPDI1's (not read)
        self.no_corners = (np.zeros((0, self.d, self.d)), np.zeros((0, self.d)), np.zeros((0, self.d)))
        if self.exact:  # the cells' vertices and bounding boxes, the most pieces of a box so far
            geo = state.particles.locator.geometry
            nodes = geo.x[geo.dofmap[:, : CELLS[self.cell][1]]]
            self.vertices = np.ascontiguousarray(nodes)
            self.bounds = np.ascontiguousarray(nodes.min(axis=1)), np.ascontiguousarray(nodes.max(axis=1))
            self.pieces = 2**self.d
            self.frontier = frontier_cells(state.particles.sample_locator)
        self.signs = corner_signs(self.d)
        self.generic: SingleFieldGrid | None = None  # for steps with samples beyond the ghost cells
        self.stencil: tuple = (np.zeros((0, 0), dtype=np.int32),)  # the samples' cells, coordinates, weights
        self._arrays: dict = {}  # kept sample arrays (_kept)
        self._corner_weights: tuple | None = None  # CPDI2: (corners, w, g, corners not found) after the last move
        self.moved: tuple | None = None  # CPDI2: (corners, twisted count) of the moving pass that moved them

    def for_step(self) -> Grid:
        super().for_step()
        missing = self._samples()
        p = self.state.particles
        if (p.comm.allreduce(missing) if p.comm.size > 1 else missing) or not self._mass_ready():
            if self.generic is None:
                self.generic = SingleFieldGrid(self.state)
            return self.generic
        return self

    def _mass_ready(self) -> bool:
        """The consistent mass's blocks of this step, whether they hold every particle's samples
        (:meth:`fempm.stepping.consistent.DomainConsistentMass.prepare`); True for the other masses.
        Collective."""
        return self.mass.prepare() if isinstance(self.mass, DomainConsistentMass) else True

    def _samples(self) -> int:
        """Make this step's samples (cells, reference coordinates, weights); returns the number
        left on no local cell (0 on one rank)."""
        p = self.state.particles
        dom = self.options.particle_domain
        d = self.d
        n, Q = len(p), len(self.signs)
        if self.exact:
            return self._box_samples()
        if self.cpdi1:
            return self._corners()
        if isinstance(dom, CPDI2):  # the tracked corners
            corners = dom.corners(p)
            n, Q, _ = corners.shape
            y = np.ascontiguousarray(corners.reshape(n * Q, d))
            kept = self._corner_weights
            if kept is not None and kept[0] is corners:  # the corners the last step moved
                w, g, missing = kept[1:]
                if missing is not None:  # and located, in self.stencil
                    return self._place(y, *self.stencil[:2], w, "clamp") if missing else 0
            else:
                w, g, _, _ = domain_geometry(corners, p.comm)
            beyond = "clamp"
        else:
            smp = dom.samples(p)
            n, Q, _ = smp.x.shape
            y, w, g, beyond = np.ascontiguousarray(smp.x.reshape(n * Q, d)), smp.w, self.no_gradient_weights, smp.beyond
        loc = p.sample_locator  # owned and ghost cells
        # the last step's sample cells are the first guess (a guess only: after the particles were
        # sorted or migrated a wrong one costs a search)
        guess = self.stencil[0] if self.stencil[0].shape == (n, Q) else None
        sc, Y, missing = locate_samples(y, p.cells, Q, self.x0, self.K, loc.vertex_star(), self.cell, loc.tol,
                                           guess, self._kept("located", n, Q))
        if missing:
            missing = self._place(y, sc, Y, w, beyond)
        self.stencil = (sc, Y, np.ascontiguousarray(w), g, *self.no_corners)
        return missing

    def _corners(self) -> int:
        """CPDI1: the corners made and located in one pass (:func:`fempm.kernels.cpdi1.locate_corners`),
        their weights left to the passes (from F at the start of the step: a copy of it where the
        stress is updated before the forces are mapped, USF); returns the number left on no
        local cell."""
        p = self.state.particles
        n, Q = len(p), len(self.signs)
        F, lp = p.fields["F"], np.ascontiguousarray(half_widths(p))
        if not self.options.stages.forces_with_map:
            kept = self._kept("F", n, Q)[0]
            np.copyto(kept, F)
            F = kept
        loc = p.sample_locator
        guess = self.stencil[0] if self.stencil[0].shape == (n, Q) else None
        sc, Y, missing = locate_corners(p.x, F, lp, self.signs, p.cells, self.x0, self.K, loc.vertex_star(), self.cell,
                                        loc.tol, guess, self._kept("located", n, Q))
        if missing:  # the corners of the particles with one the search did not find (the rows _place reads)
            parts = np.flatnonzero((sc < 0).any(axis=1))
            y = np.empty((n * Q, self.d))
            y[(parts[:, None] * Q + np.arange(Q)).ravel()] = cpdi1_samples(p.x[parts], F[parts], lp[parts],
                                                                           self.signs)[0]
            missing = self._place(y, sc, Y, self.no_weights, "clamp")
        self.stencil = (sc, Y, self.no_weights, self.no_gradient_weights, F, lp, self.signs)
        return missing

    def _box_samples(self) -> int:
        """Exact GIMP: the pieces of the particles' boxes in the cells as samples
        (:func:`fempm.kernels.boxes.box_samples`); returns the number of boxes that may reach
        cells this rank does not have (or meet more cells than the kernel searches)."""
        p = self.state.particles
        ell = half_widths(p, self.options.particle_domain.deform)
        cell_type = CELLS[self.cell][0], CELLS[self.cell][2]
        while True:
            guessed = ("boxes", len(p), self.pieces) in self._arrays  # the last step's samples
            out = self._kept("boxes", len(p), self.pieces)
            needed, reaching, failed = box_samples(p.x, ell, p.cells, cell_type, self.vertices, self.bounds,
                                                   p.sample_locator.vertex_star(), self.frontier, self.x0,
                                                   self.K, out, guessed)
            if needed <= self.pieces:
                break
            self.pieces = needed  # and again with room for every piece
        self.stencil = (*out, self.no_gradient_weights, *self.no_corners)
        return reaching + failed

    def _kept(self, what: str, n: int, Q: int) -> tuple:
        """Arrays kept from step to step for ``n`` particles of ``Q`` samples (made anew when
        ``n`` changes): a copy of F (CPDI1 with USF), the located samples (cells, coordinates) or
        the exact GIMP ones (cells, coordinates, weights)."""
        key = (what, n, Q)
        if key not in self._arrays:
            self._arrays = {k: a for k, a in self._arrays.items() if k[0] != what}
            d = self.d
            self._arrays[key] = {"F": lambda: (np.empty((n, d, d)),),
                                 "located": lambda: (np.full((n, Q), -1, dtype=np.int32), np.zeros((n * Q, d))),
                                 "boxes": lambda: (np.empty((n, Q), dtype=np.int32), np.empty((n * Q, d)),
                                                   np.empty((n, Q)))}[what]()
        return self._arrays[key]

    def _place(self, y: npt.NDArray, sc: npt.NDArray, Y: npt.NDArray, w: npt.NDArray, beyond: str) -> int:
        """The samples the vertex-star search did not find: located through the tree; on one rank
        those beyond the mesh clamped or cut (as :class:`~fempm.transfer.basis.ParticleBasis`).
        Returns the number left on no local cell (several ranks)."""
        p = self.state.particles
        loc = p.sample_locator
        Q = sc.shape[1]
        rows = np.flatnonzero(sc.ravel() < 0)
        cells, X = loc.locate(y[rows])
        found = cells >= 0
        sc.ravel()[rows[found]] = cells[found]
        Y[rows[found]] = X[found]
        rows = rows[~found]
        if p.comm.size > 1 or len(rows) == 0:
            return len(rows)
        if beyond == "cut":  # Gauss GIMP: drop the points beyond the mesh, renormalise
            part = rows // Q
            w.ravel()[rows] = 0.0
            sc.ravel()[rows] = p.cells[part]
            Y[rows] = p.X[part]
            total = w.sum(axis=1)
            if np.any(total <= 0):
                raise ValueError(f"{self.options.particle_domain.name} particle domains with no sample point inside "
                                 "the mesh")
            w /= total[:, None]
            return 0
        cells, X = loc.locate(loc.closest_on_mesh(y[rows]))  # CPDI: at the closest point of the mesh
        if np.any(cells < 0):
            raise RuntimeError("a clamped sample point was not found on the mesh")
        sc.ravel()[rows], Y[rows] = cells, X
        return 0

    def to_particles(self, v_new: npt.NDArray, v_old: npt.NDArray, dt: float, *, blend: bool = False,
                     kinematics: bool = False, move: bool = False, remap: bool = False) -> None:
        """The passes of :class:`~fempm.stepping.lumped.PointGrid`; with domains tracked by their
        corners (CPDI2) the moving pass also moves the corners with the grid velocity at them and
        each particle to its domain's centroid with its volume (the scalar 2D passes,
        ``corners=`` of :func:`fempm.kernels.samples.kernels_for`), or a pass after it does
        (:func:`fempm.kernels.sample_location.at_samples`, :meth:`fempm.transfer.domains.CPDI2.move`)."""
        tracked = move and self.options.particle_domain.tracks_corners
        self.moved = None
        super().to_particles(v_new, v_old, dt, blend=blend, kinematics=kinematics, move=move, remap=remap)
        if not tracked:
            return
        s = self.state
        p = s.particles
        if self.moved is not None:  # moved and located in the pass
            corners, bad = self.moved
            w, g = self.stencil[2:4]
            missing = int(bad[1])
            if p.comm.allreduce(int(bad[0])) if p.comm.size > 1 else bad[0]:
                s.fail(f"inverted particle domain: {int(bad[0])} CPDI2 domain(s) on this rank are degenerate or "
                       "twisted (corner Jacobian zero or changing sign)")
        else:
            sc, Y = self.stencil[:2]
            at = at_samples(self.cell, sc, Y, self.K, self.cell_dofs, v_new)
            corners = p.fields["corners"] + dt * at
            try:
                w, g, volume, centroid = domain_geometry(corners, p.comm)
            except ValueError as e:  # collective
                s.fail(f"inverted particle domain: {e}")
            p.x, p.volume = centroid, volume
            self.left = None  # moved to their centroids: relocated from their cells (Particles.relocate)
            missing = None  # the corners are located at the next step
        p.fields["corners"] = corners
        self._corner_weights = (corners, w, g, missing)  # the next step's, while the particles keep this array

    def samples(self) -> Samples:
        """The averaged basis of the step: the samples (``stencil``) and the space's cells."""
        return Samples(*self.stencil, self.K, self.cell_dofs)

    def scatter_pass(self, state: State, forces: Forces, out, cm: int, cv: int, cf: int, stable: Stable, *,
                     bound: bool = False, groups: Groups = NO_GROUPS, cg: int = -1, affine=None, kind: int = 0) -> float:
        p = self.state.particles  # (no affine transfer: see transfers)
        return self.passes.scatter(Basis(p.cells, p.X, self.K, self.cell_dofs), self.samples(), state, self.laws,
                                   forces, out, cm, cv, cf, stable, bound)

    def mass_apply(self, y: npt.NDArray, lump: npt.NDArray, out: npt.NDArray) -> None:
        """FMPM's :math:`M_C y` with the averaged basis (the samples' ``mass_apply``)."""
        p = self.state.particles
        self.passes.mass_apply(Basis(p.cells, p.X, self.K, self.cell_dofs), self.samples(), p.mass, y, lump, out)

    def gather_pass(self, grid: GridStep, state: State, moves: Moves, outputs: Outputs, *, blend: bool,
                    kinematics: bool, move: bool) -> tuple:
        p = self.state.particles
        corners = None
        if move and self.passes.tracks and self.options.particle_domain.tracks_corners:  # CPDI2: corners moved here
            yc = np.ascontiguousarray(p.fields["corners"], dtype=np.float64)
            corners = Corners(yc, np.empty_like(yc), np.zeros(2, dtype=np.int64), p.sample_locator.vertex_star()[3])
            self.moved = (corners.moved, corners.bad)
        return self.passes.g2p_update(Basis(p.cells, p.X, self.K, self.cell_dofs), self.samples(), grid, state,
                                      self.laws, moves, outputs, blend=blend, kinematics=kinematics, move=move,
                                      corners=corners)
