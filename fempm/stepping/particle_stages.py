r"""The particles' side of a step, shared by the numpy grids (:class:`fempm.stepping.grid.BasisGrid`)
and the implicit step (:class:`fempm.implicit.step.ImplicitStep`), which compose it: the checks
that open a step and its particle basis, the kinematics and the laws' stress
(:math:`F_p^+ = (I + \Delta t L_p) F_p`, :math:`V_p = J_p V_p^0`), the particle domains'
motion, the finite-state check and the relocation."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm import kernels
from fempm.stepping.laws import material_groups, stresses_of
from fempm.stepping.state import StepState
from fempm.transfer.basis import ParticleBasis

__all__ = ["ParticleStages"]


class ParticleStages:
    """The particle stages of a step of ``state`` (see the module)."""

    def __init__(self, state: StepState):
        self.state = state
        self.options = state.options

    def open_basis(self) -> ParticleBasis:
        """The checks that open a step and its particle basis (values and gradients). Collective."""
        s = self.state
        s.check_state()
        basis = ParticleBasis(s.V, s.particles, gradients=True, domain=self.options.particle_domain)
        s.record.extended_steps += basis.extended
        return basis

    def update_kinematics(self, L: npt.NDArray, dt: float, averaged: bool = True,
                          basis: ParticleBasis | None = None) -> None:
        r""":math:`F_p^+ = (I + \Delta t L_p) F_p`, :math:`V_p = J_p V_p^0` and the laws' stress,
        with the checks of J (one collective); with F-bar :math:`L_p` is first replaced by
        :math:`\bar L_p` (:meth:`fempm.stepping.fbar.FBar.rate`, over the step's ``basis``)
        unless ``averaged`` is False (the implicit step's :math:`L_p` are averaged already)."""
        s = self.state
        p = s.particles
        f = p.fields
        average = self.options.volumetric_average
        if average is not None and averaged:  # F-bar: the increments' volume change averaged over the patches
            if basis is None:
                raise ValueError("F-bar's averaged rate needs the step's particle basis")
            L = average.rate(basis, p.volume, f["body"], s.materials, f["F"], L, dt)
        F, J = kernels.deform(f["F"], L, dt)
        nonfinite = ~np.isfinite(J)
        bad = J <= 0
        finite = J[~nonfinite]
        flags = np.array([nonfinite.any(), bad.any(), -finite.min(initial=np.inf), finite.max(initial=-np.inf)],
                         dtype=float)
        p.comm.Allreduce(MPI.IN_PLACE, flags, op=MPI.MAX)  # one collective: both checks and the J range
        if flags[0]:
            s.fail(f"non-finite state (deformation gradient) at particle(s) {s.particle_ids(nonfinite)}")
        if flags[1]:
            s.fail(f"inverted deformation J <= 0 at particle(s) {s.particle_ids(bad)}")
        s.record.j_range = (-float(flags[2]), float(flags[3]))
        f["F"] = F
        p.volume = J * f["volume0"]
        stresses_of(p.comm, material_groups(f, s.materials), F, L, f["sigma"], dt, p.mass / p.volume, f)

    def move(self, at_grid: npt.NDArray, corner_velocity, dt: float) -> None:
        """The particle domain's motion (:meth:`fempm.transfer.domains.Domain.move`) with the grid
        velocity at the particles ``at_grid`` and at the corners ``corner_velocity()``."""
        s = self.state
        try:
            self.options.particle_domain.move(s.particles, at_grid, corner_velocity, dt,
                                              self.options.particle_position)
        except ValueError as e:  # collective
            s.fail(f"inverted particle domain: {e}")

    def close(self) -> None:
        self.state.check_finite()

    def relocate(self) -> None:
        self.state.relocate_particles()
