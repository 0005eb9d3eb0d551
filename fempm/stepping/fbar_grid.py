r"""F-bar on the compiled point grid (:class:`FBarPointGrid`): ``StepOptions(volumetric="fbar")``
with point particles in compiled passes.

The equations are those of :mod:`fempm.stepping.fbar` (the numpy :class:`~fempm.stepping.grid.SingleFieldGrid`
with :class:`~fempm.stepping.fbar.FBar` is the reference this grid is tested against to
round-off). Two stages of :class:`~fempm.stepping.lumped.PointGrid` change:

* the kinematics: the G2P pass is split at the law. A first pass (:func:`fempm.kernels.fbar.measure_kernel`)
  computes :math:`L_p` and the measure the law averages and adds the measure to nodal patch sums;
  once the ghosts are summed the point grid's pass interpolates the average back and sets
  :math:`\bar F_p`, :math:`V_p` and the stress with the blend and the motion (on triangles and
  quadrilaterals, :func:`fempm.kernels.planar.g2p_kernel`, which computes :math:`L_p` and the
  measure again rather than reading them back), or a second pass does
  (:func:`fempm.kernels.fbar.deform_kernel`) before the point grid's pass without kinematics;
* the internal force: each P2G pass that maps forces takes :math:`\sigma_p + (\bar p_p - p_p) I`,
  the pressures first summed on the nodes and averaged inside the P2G pass (``Forces.patch``).
  On triangles and quadrilaterals the kinematics pass sums them where each particle ends it, for
  the next force pass, on tetrahedra and affine hexahedra the moving pass after the second
  (:func:`fempm.kernels.solid.g2p_kernel`, ``pressures``); a pass of their own
  (:func:`fempm.kernels.fbar.pressure_kernel`) sums them where the particles changed since (left
  their cells' neighbours, changed ranks, were set from outside: new arrays), after a moving pass
  without kinematics (USF), for the planar passes' laws without a compiled kernel (which set
  their stress after the pass) and on the other cells.

So a step costs one (triangles, quadrilaterals) or two (tetrahedra, affine hexahedra) more
particle passes than the point step (three on the other cells)
and two ghost exchanges of a (dofs, 2 B) array of B bodies; the sums are cleared and averaged in
the blocks of dofs the passes wrote (:mod:`fempm.kernels.patch`). Every option of the point grid
is taken (lumped, consistent and FMPM mass, every scheme and transfer, every cell and degree of
the compiled passes).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from fempm.kernels import fbar as kb
from fempm.kernels.bundles import NO_AFFINE, NO_GROUPS, Affine, Averaged, Basis, Forces, Groups, Stable, State
from fempm.kernels.lumped import PLANAR, SOLID
from fempm.kernels.patch import BLOCK_SHIFT, averages, blocks, clear_blocks
from fempm.stepping.fbar import trace_measure
from fempm.stepping.lumped import PointGrid
from fempm.stepping.nodal import exchanged_rows, sum_ghosts
from fempm.stepping.state import StepState

__all__ = ["FBarPointGrid"]


class PatchSums:
    """A kept (dofs, 2 B) array of nodal patch sums of B bodies with the dirty marks of its blocks
    (:mod:`fempm.kernels.patch`): cleared and averaged where the passes wrote, not at every dof."""

    def __init__(self, grid: PointGrid, bodies: int):
        self._vec, self.array = grid.nodal_array(2 * bodies)  # [sum V N | sum V N f] per body
        self._always = np.zeros(blocks(len(self.array)), dtype=np.uint8)  # the blocks a ghost exchange writes
        self._always[np.flatnonzero(exchanged_rows(grid.index_map)) >> BLOCK_SHIFT] = 1
        self.dirty = np.ones_like(self._always)  # the blocks written since the last clear: all at first

    def zeroed(self) -> tuple[npt.NDArray, npt.NDArray]:
        """The sums, zeroed, and the dirty marks the passes that add to them set."""
        clear_blocks(self.array, self.dirty, self._always)
        return self.array, self.dirty

    def averaged(self) -> npt.NDArray:
        """The sums summed over ranks and turned into nodal averages
        (:func:`fempm.kernels.patch.averages`). Collective."""
        sum_ghosts(self._vec)
        averages(self.array, self.dirty)
        return self.array


class FBarPointGrid(PointGrid):
    """The point grid's stages with F-bar's averaged kinematics and pressure (see the module)."""

    takes = "point particles with F-bar (volumetric='fbar'), as PointGrid"

    def __init__(self, state: StepState):
        super().__init__(state)
        bodies = len(state.materials)
        self.by_trace = trace_measure(state.materials)
        self._patch = PatchSums(self, bodies)  # the measures'
        self._at_pressures = PatchSums(self, bodies)  # the pressures'
        #: the particle arrays (``_state``) the planar kinematics pass left the pressure sums of, else None
        self._carried = None
        self._measure = kb.measure_kernel(self.cell)
        self._deform = kb.deform_kernel(self.cell, self.any_external)
        self._pressures = kb.pressure_kernel(self.cell)
        self._L, self._value = np.empty((0, self.d, self.d)), np.empty(0)  # kept: L_p and the measures (not planar)

    def where(self) -> Basis:
        """The particles' basis bundle."""
        p = self.state.particles
        return Basis(p.cells, p.X, self.K, self.cell_dofs)

    def pressure_sums(self) -> npt.NDArray:
        """The nodal averages of the particles' pressures where they are, for the P2G pass: of the
        sums the planar kinematics pass left where the particles have not changed since (none
        left their cells' neighbours, the arrays are the same), else of a pass of their own; one
        ghost exchange. Collective."""
        if self._carried is None or self._carried != self._state():
            p = self.state.particles
            f = p.fields
            self._pressures(self.where(), p.volume, f["sigma"], f["body"], *self._at_pressures.zeroed())
        self._carried = None
        return self._at_pressures.averaged()

    def scatter_pass(self, state: State, forces: Forces, out, cm: int, cv: int, cf: int, stable: Stable, *,
                     bound: bool = False, groups: Groups = NO_GROUPS, cg: int = -1, affine: Affine = NO_AFFINE,
                     kind: int = 0) -> float:
        """The point grid's P2G pass; where it maps forces, with the patch-averaged pressure."""
        if cf >= 0:
            forces = Forces(forces.g, forces.fext, self.pressure_sums())
        return super().scatter_pass(state, forces, out, cm, cv, cf, stable, bound=bound, groups=groups, cg=cg,
                                    affine=affine, kind=kind)

    def particle_pass(self, v_new, v_old, dt, *, blend: bool, kinematics: bool, move: bool, remap=None):
        """The averaged kinematics (two passes, one ghost exchange, the checks of J), then the
        point grid's pass for the blend, the re-map and the motion (on triangles and
        quadrilaterals one pass, which also sums the next force pass's pressures)."""
        if not kinematics:
            if move:
                self._carried = None
            return super().particle_pass(v_new, v_old, dt, blend=blend, kinematics=False, move=move, remap=remap)
        self._carried = None
        p = self.state.particles
        f = p.fields
        where = self.where()
        n = len(p)
        if len(self._value) != n and self.cell not in PLANAR:  # (the planar G2P pass computes both again)
            self._L, self._value = np.empty((n, self.d, self.d)), np.empty(n)
        L, value = self._L, self._value
        self._measure(where, v_new, f["F"], p.volume, f["body"], self.by_trace, float(dt), L, value,
                      *self._patch.zeroed())
        patch = self._patch.averaged()
        if self.cell in PLANAR:  # the averaged kinematics inside the point grid's pass
            carry = not self.any_external  # (the laws without a compiled kernel set their stress after it)
            sums = self._at_pressures.zeroed() if carry else ()
            average = Averaged(patch, self.by_trace, len(self.by_trace), *sums)
            nonfinite, left = super().particle_pass(v_new, v_old, dt, blend=blend, kinematics=True, move=move,
                                                    remap=remap, average=average)
            if carry and not (move and left.any()):
                self._carried = self._state()
            return nonfinite, left
        counts = self._deform(where, patch, self.by_trace, float(dt), L, value, self.particle_state(),
                              self.laws)
        nonfinite = self.kinematics_checks(counts, L if self.any_external else None, dt)
        left = np.empty(0, dtype=np.bool_)
        if blend or move or remap is not None:  # (tetrahedra, hexahedra: the moving pass sums the pressures)
            carry = move and self.cell in SOLID
            average = None
            if carry:
                average = Averaged(patch, self.by_trace, len(self.by_trace), *self._at_pressures.zeroed())
            more, left = super().particle_pass(v_new, v_old, dt, blend=blend, kinematics=False, move=move, remap=remap,
                                               average=average)
            nonfinite += more
            if carry and not left.any():
                self._carried = self._state()
        return nonfinite, left
