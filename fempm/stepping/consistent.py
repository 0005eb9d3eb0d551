r"""The consistent-mass step for point particles on affine degree-1 cells, in compiled passes.

The lumped step's passes (:mod:`fempm.stepping.lumped`: P2G, G2P with the kinematics and the laws,
motion and relocation) with the grid update of :meth:`fempm.stepping.ExplicitSolver.step`
for ``mass="consistent"``, its reference:

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

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from fempm.kernels import consistent as kc
from fempm.stepping.lumped import LumpedPointStep
from fempm.stepping.mass_systems import ConsistentSystems
from fempm.stepping.nodal import sum_ghosts
from fempm.stepping.options import MASS_RATIO_ITERATIONS, MASS_RATIO_SAFETY

if TYPE_CHECKING:
    from fempm.stepping.solver import ExplicitSolver

#: steps between two refreshes of the stable-step estimate when ``dt`` is given
RATIO_EVERY = 20


class ConsistentPointStep(LumpedPointStep):
    """The compiled consistent step of an :class:`~fempm.stepping.ExplicitSolver` (see the module)."""

    def __init__(self, solver: ExplicitSolver):
        super().__init__(solver)
        self.fused = False  # the grid update solves with the consistent matrix
        fixed = np.zeros(self.num_dofs, dtype=np.bool_)
        if solver._fixed_dofs is not None:
            fixed[solver._fixed_dofs] = True
        self.systems = ConsistentSystems(solver.V, self.cell_dofs, self.free, fixed,
                                         prefix=self.options.petsc_options_prefix,
                                         lump_below=self.options.lump_below,
                                         always_lumped=solver.node_local_dofs)
        self.cell_mass = kc.cell_mass(solver.particles.locator.geometry.cell_name)
        self._ghosted = self._nodal_array(self.d)
        self._accel: npt.NDArray | None = None  # the last acceleration, the warm start of its solve
        self._spare: npt.NDArray | None = None  # the array of the acceleration before it
        self._ratio_age = RATIO_EVERY
        self._ratio_key = -1

    def _stable_factor(self, nodal, need: bool) -> float:
        """The mass pass and the matrices' values; :math:`\\sqrt{0.8\\,\\lambda_{min}}` (1 with
        lumped forces)."""

        s = self.solver
        p = s.particles
        sy = self.systems
        while True:
            blocks, diagonal, count, dvec = sy.work_arrays()
            missing = self.cell_mass(p.cells, p.X, self.K, self.cell_dofs, p.mass, sy.pattern, blocks, diagonal,
                                     count)
            if not p.comm.allreduce(missing):
                break
            sy.rebuild(p.cells)
        sum_ghosts(dvec[0])
        sy.update(diagonal, nodal[:, 0], p.num_global)
        if self.options.lumped_forces:
            return 1.0
        key = sy.rebuilds
        self._ratio_age += 1
        if need or key != self._ratio_key or self._ratio_age >= RATIO_EVERY:
            s.mass_ratio = sy.mass_ratio_min(s.V, MASS_RATIO_ITERATIONS)
            self._ratio_key, self._ratio_age = key, 0
        return float(np.sqrt(MASS_RATIO_SAFETY * s.mass_ratio))

    def checkpoint_arrays(self) -> dict[str, npt.NDArray]:
        """This rank's state that a resumed run needs to repeat the next steps bit for bit: the
        warm start of the acceleration solve, the kept systems (:meth:`ConsistentSystems.state`)
        and the stable-step estimate's key."""
        out = {f"mass:{k}": v for k, v in self.systems.state().items()}
        out["ratio_key"] = np.array([self._ratio_key])
        if self._accel is not None:
            out["accel"] = self._accel
        return out

    def restore_arrays(self, arrays: dict[str, npt.NDArray]) -> None:
        """The state of :meth:`checkpoint_arrays` (from a run on as many ranks; an empty dict
        on another number of ranks: the next steps then agree to round-off). Collective."""
        self._accel = arrays.get("accel")
        if "ratio_key" in arrays:
            self._ratio_key = int(arrays["ratio_key"][0])
        self.systems.restore({k[5:]: v for k, v in arrays.items() if k.startswith("mass:")})

    def _ghosts(self, u: npt.NDArray) -> npt.NDArray:
        """Owned values of ``u`` (dofs, d) to the ghosts (in place)."""
        vec, arr = self._ghosted
        if vec is not None:
            arr[:] = u
            vec.scatter_forward()
            u[:] = arr
        return u

    def _grid_velocity(self, mass, mom, cv: int, active_min: float, guess=None, centroids=None) -> npt.NDArray:
        v = np.zeros((self.num_dofs, self.d))
        self.systems.solve(mom, cv, v, guess)
        self.solver._apply_bcs(v, centroids)
        return self._ghosts(v)

    def _advance(self, mass, force, cf: int, active_min: float, weak_max: float, dt: float,
                 v_old: npt.NDArray, centroids=None) -> npt.NDArray:
        s = self.solver
        opts = s.options
        sy = self.systems
        a = self._spare if self._spare is not None else np.zeros((self.num_dofs, self.d))
        if opts.lumped_forces:
            m = mass[:, 0]
            a[sy.active] = force[sy.active, cf:cf + self.d] / m[sy.active, None]
        else:
            sy.solve(force, cf, a, self._accel)  # every owned entry of a written
            self._ghosts(a)
            self._accel, self._spare = a, self._accel  # the next warm start; the next output
        v_new = np.empty_like(a)
        kc.advance(a, v_old, mass[:, 0], weak_max, float(dt), float(opts.damping), v_new)
        s._apply_bcs(v_new, centroids)
        return self._ghosts(v_new)
