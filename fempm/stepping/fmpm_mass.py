r"""FMPM(k) as the grid mass of the compiled passes (:class:`FMPMNodalMass`).

The passes of :class:`fempm.stepping.lumped.PointGrid` with the grid update of FMPM(k)
(:mod:`fempm.transfer.fmpm`), whose reference is :class:`~fempm.stepping.grid.SingleFieldGrid`
with ``mass="fmpmK"``: the velocity and the acceleration are each k Richardson steps from the
lumped solve,

.. math::
    x \leftarrow x + m^{-1} (b - M_C x), \qquad (M_C x)_i = \sum_p M_p N_{ip} \sum_j N_{jp} x_j,

every step after the first one compiled particle pass (the grid's ``mass_apply``:
:func:`fempm.kernels.fmpm.mass_apply`, or with particle domains its form over the samples,
:mod:`fempm.kernels.samples`; no matrix) and one ghost exchange. Solved on the free components of the supported dofs; the
rows and columns of dofs whose lumped mass is below ``lump_below`` of the largest, and of
frictional walls, are lumped (they keep the lumped value); the acceleration is 0 where the
lumped mass is below ``mass_cutoff``; the stable step is :math:`1/\sqrt{k}` of the lumped one
(1 with ``lumped_forces``, which divides the forces by the lumped mass).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from fempm.kernels import consistent as kc
from fempm.kernels import fmpm as kf
from fempm.stepping.nodal import NodalLayout, NodalMass, sum_ghosts

__all__ = ["FMPMNodalMass"]

NO_ROWS = np.zeros((0, 0))  # no array to clear (lumped_solve)


class FMPMNodalMass(NodalMass):
    """FMPM(k) as the grid mass of a :class:`~fempm.stepping.lumped.PointGrid` (see the module)."""

    fusable = False  # the grid update takes particle passes

    def __init__(self, layout: NodalLayout, order: int | None = None):
        super().__init__(layout)
        #: the k of FMPM(k) (the mass model's, or another: XPIC's m)
        self.order = layout.options.mass_model.order if order is None else order
        self._work: dict = {}  # (columns, lumping) -> kept nodal array of M_C y (and M_C 1_l)
        self._acceleration: tuple | None = None  # (force array, column, a): solved with the velocity
        self._free = {1: layout.free}  # fields side by side -> their free components (layout.free is the run's)
        self.friction = layout.conditions.friction_dofs
        self.lump = np.zeros(0, dtype=np.bool_)

    def stable_factor(self, nodal, need: bool, top: float) -> float:
        r"""The lumped rows of this step; :math:`1/\sqrt{k}` (1 with lumped forces)."""
        g = self.layout
        m = nodal[:, 0]
        lump = m < g.options.lump_below * top if g.options.lump_below > 0.0 else np.zeros(len(m), dtype=np.bool_)
        if self.friction is not None:
            lump[: len(self.friction)] |= self.friction[: len(lump)]
        self.lump = lump if lump.any() else np.zeros(0, dtype=np.bool_)
        if g.options.lumped_forces:
            return 1.0
        return 1.0 / float(np.sqrt(self.order))

    def work(self, columns: int) -> tuple:
        """The kept nodal arrays (vector, array) of :meth:`mc` for ``columns`` columns."""
        key = (columns, len(self.lump) > 0)
        if key not in self._work:
            self._work[key] = self.layout.nodal_array(key[0] + key[1])
            self._work[key][1].fill(0.0)  # rows without mass are never cleared (nor read)
        return self._work[key]

    def mc(self, y: npt.NDArray) -> npt.NDArray:
        """:math:`M_C y` without the lumped dofs (and :math:`M_C 1_l` in one more column where
        rows are lumped) on every local dof, ghosts summed and updated, into the array of
        :meth:`work` (its rows with mass cleared by the pass over the dofs before: the lumped
        solve or the last Richardson step)."""
        vec, out = self.work(y.shape[1])
        self.layout.mass_apply(y, self.lump, out)
        sum_ghosts(vec)
        return out

    def solve(self, mass: npt.NDArray, b: npt.NDArray, cb: int, active_min: float, fields: int = 1,
              start: npt.NDArray | None = None) -> list:
        r"""k Richardson steps :math:`x \leftarrow x + m^{-1}(b - M_C x)` from :math:`x = m^{-1} b`
        (``b[:, cb:cb+d]``, ``m = mass[:, 0]``) on the free components of the supported dofs
        (lumped rows keep :math:`m^{-1} b`); ``fields`` vector fields side by side
        (``b[:, cb:cb+fields*d]``), each column solved as on its own, in one particle pass a
        step. ``start`` (dofs, d): a term of the first field's lumped solve alone,
        :math:`x = m^{-1}(b + s)` (the affine part of APIC/TPIC, :mod:`fempm.transfer.transfers`).
        Returns the fields' solutions, each a contiguous (dofs, d) array; the passes over the dofs
        also clear the next :meth:`mc`'s output."""
        g = self.layout
        d = g.d
        if fields not in self._free:
            self._free[fields] = np.ascontiguousarray(np.tile(g.free, (1, fields)))
        free = self._free[fields]
        k = free.shape[1]
        x = np.zeros((g.num_dofs, k))  # (the kernels write the rows with mass alone)
        first, c0 = b, cb
        if start is not None:
            first = np.array(b[:, cb:cb + k])
            first[:, :d] += start
            c0 = 0
        kf.lumped_solve(first, c0, mass, free, active_min, x, self.work(k)[1] if self.order > 1 else NO_ROWS)
        if self.order == 1:
            return [np.ascontiguousarray(x[:, f * d:(f + 1) * d]) for f in range(fields)]
        for step in range(1, self.order):
            last = step == self.order - 1
            out = [np.zeros((g.num_dofs, d if last else k)), np.zeros((g.num_dofs, (k - d) if last else 0))]
            kf.richardson(x, b, cb, self.mc(x), mass, free, active_min, self.lump, *out, not last)
            x = out[0]
        return out[:fields]  # (fields = 1: the second is empty)

    def velocity(self, mass, mom, cv: int, active_min: float, guess=None, centroids=None,
                 forces: int | None = None, start: npt.NDArray | None = None) -> npt.NDArray:
        """The velocity solve; where the forces of the step sit next to the momenta in ``mom``
        (USL and MUSL: one P2G pass maps both) the acceleration is solved with it, its
        Richardson steps sharing the velocity's particle passes, and kept for :meth:`advance`;
        ``start``: the affine part of the momenta, in the first, lumped solve alone."""
        g = self.layout
        opts = g.options
        d = g.d
        if forces == cv + d and not opts.lumped_forces:
            v, a = self.solve(mass, mom, cv, active_min, fields=2, start=start)
            self._acceleration = (mom, forces, a)
        else:
            v = self.solve(mass, mom, cv, active_min, start=start)[0]
        g.conditions.apply(v, centroids)
        return v

    def advance(self, mass, force, cf: int, active_min: float, weak_max: float, dt: float, v_old: npt.NDArray,
                centroids=None) -> npt.NDArray:
        g = self.layout
        if g.options.lumped_forces:
            m = mass[:, 0]
            active = (m > active_min)[:, None]
            a = np.where(active, force[:, cf:cf + g.d] / np.where(active, m[:, None], 1.0), 0.0)
        elif self._acceleration is not None and self._acceleration[0] is force and self._acceleration[1] == cf:
            a = self._acceleration[2]  # solved with this step's velocity
        else:
            a = self.solve(mass, force, cf, active_min)[0]
        self._acceleration = None
        v_new = np.empty_like(a)
        kc.advance(np.ascontiguousarray(a), v_old, np.ascontiguousarray(mass[:, 0]), weak_max, float(dt),
                   float(g.options.damping), v_new)
        g.conditions.apply(v_new, centroids, dt)
        return v_new
