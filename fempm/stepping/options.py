"""The options of the explicit step (:class:`StepOptions`) and the step's error."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from fempm.arguments import check_numbers
from fempm.stepping.dynamics import time_integration
from fempm.stepping.fbar import volumetric
from fempm.stepping.schemes import Scheme, scheme
from fempm.transfer.domains import step_domain
from fempm.transfer.mass_models import FMPM, mass_model
from fempm.transfer.transfers import velocity_transfer

__all__ = ["AFFINE_CUTOFF", "SchemeName", "SimulationError", "StepOptions"]

#: the explicit step's ``affine_cutoff`` by default: the share of the largest nodal mass below
#: which a node passes its acceleration to APIC's and TPIC's affine matrices in proportion
#: (docs/transfers.md: 1e-3 lets a disk of 30 cells grow energy, 1e-2 holds 10 to 60 cells)
AFFINE_CUTOFF = 1e-2

#: the names of the built-in schemes (the option's values; a :class:`fempm.stepping.schemes.Scheme`
#: subclass may be given instead)
SchemeName = Literal["USL", "USF", "MUSL"]



class SimulationError(RuntimeError):
    """The state became invalid (non-finite values, J <= 0, unstable time step)."""


@dataclass
class StepOptions:
    r"""Transfer and time-stepping options, parsed once into objects (:attr:`stages`,
    :attr:`mass_model`, :attr:`particle_domain`, :attr:`integration`, :attr:`volumetric_average`)
    and flags (:attr:`particle_position`, :attr:`finite_difference_tangent`).

    Args:
        scheme: The update scheme: USL, USF or MUSL. The stability catalogue (``python -m fempm
            study stability``) found MUSL with lumped mass stable in 9 of its 13 hard cases and
            at every CFL number up to 1 on the colliding disks, USL in 3 and up to CFL 0.25
            (docs/error-vs-time-and-stability.md).
        flip: The PIC/FLIP blend alpha in [0, 1] (1: FLIP, 0: PIC) of ``transfer="flip"``
            (the other transfers take no blend and leave it unread).
        transfer: The velocity transfer (:mod:`fempm.transfer.transfers`): flip (the blend
            ``flip``), pic (``flip=0``), apic (affine PIC: the particles carry :math:`B_p`,
            angular momentum kept), tpic (the particles carry their velocity gradient) or xpic
            (extended PIC of order ``xpic_order``: the lumped velocities extrapolated by the
            series FMPM sums before G2P). APIC and TPIC keep a particle field ``affine`` (n, d, d).
        xpic_order: XPIC's m, an integer in [1, 10] (XPIC(1) is PIC).
        affine_cutoff: APIC and TPIC: G2P takes the particles' affine matrices from
            :math:`v_i + w_i (v_i^+ - v_i)`, :math:`w_i = \min(1, m_i / (c \max_j m_j))` with
            this c, so that nodes with a small share of mass do not feed their large
            accelerations back through :math:`\nabla N` (:func:`fempm.transfer.affine.affine_velocity`;
            APIC's spin, and with it the angular momentum, stays that of :math:`v^+`). None:
            :data:`AFFINE_CUTOFF` with the explicit step, 0 with the implicit one; 0: the
            updated grid velocity itself (unstable at the CFL step on fine grids).
        mass: The grid mass: lumped, consistent, or FMPM(k) as fmpmK (or ``fmpm`` with
            ``fmpm_order`` k). FMPM(k) (:mod:`fempm.transfer.fmpm`) takes k - 1 extra G2P/P2G
            sweeps, and a step :math:`1/\sqrt{k}` of the lumped one unless ``lumped_forces``.
        cfl: The Courant number of the time step, in (0, 1].
        mass_cutoff: Nodes whose lumped mass (P2 Lagrange: :math:`\sum_p M_p |N_{ip}|`) is below
            this fraction of the largest get no force update (they keep the mapped velocity).
        position: grid (move the particles with the grid velocity) or particle (with their own
            updated velocity, :math:`x_p^+ = x_p + \Delta t\, v_p^+`).
        lumped_forces: With consistent mass, divide the forces by the lumped mass (stable with
            the CFL step where weakly supported boundary nodes make the consistent matrix
            nearly singular).
        lump_below: With consistent mass, lump the rows whose lumped mass is below this
            fraction of the largest (free-surface rims; raises the stable step).
        domain: The particle domain: point, gimp, ugimp, cpgimp, cpdi1 or cpdi2. point is
            standard MPM; gimp a box average, exact or with ``gimp_order`` Gauss points per axis
            (uGIMP, or cpGIMP with ``gimp_deform``; ugimp and cpgimp name them); cpdi1
            parallelograms that follow F; cpdi2 domains tracked by their corners
            (:mod:`fempm.transfer.domains`).
        gimp_order: Gauss points per axis of GIMP's box average (None: exact).
        gimp_deform: Stretch GIMP's boxes by the diagonal of F (cpGIMP).
        petsc_options_prefix: The PETSc options prefix of the consistent mass solves.
        damping: The mass-proportional damping rate :math:`c` (1/s) of the grid acceleration,
            :math:`a_i \leftarrow a_i - c\, v_i` (:math:`c \approx 2\omega_1` damps the lowest
            mode critically; a static solution is left as it is).
        fmpm_order: The k of ``mass="fmpm"``.
        integrator: explicit, or implicit (:mod:`fempm.implicit`: Newton's method on PETSc SNES,
            options prefix ``fempm_implicit_``, for the grid's displacement increment).
        dynamics: Implicit: newmark (``newmark_beta``, ``newmark_gamma``; the trapezoidal rule
            by default) or quasi-static.
        newmark_beta: Newmark's beta, in (0, 1/2].
        newmark_gamma: Newmark's gamma, in [1/2, 1].
        tangent: Implicit: analytic (the laws' own ``tangent``) or finite-difference (central
            differences of the stress update, for a law without one).
        max_cuts: Implicit: how often a step that does not converge is halved before the run
            stops.
        load_ramp: Implicit, quasi-static: the loads scaled by :math:`\min(1, t / t_{ramp})` at
            a step's end time t (None: the loads as given).
        volumetric: standard, or fbar (:mod:`fempm.stepping.fbar`: each particle's volume
            change averaged over its nodal patch, against volumetric locking; the compiled
            :mod:`fempm.stepping.fbar_grid` for point particles, the numpy step for the others,
            and the implicit step with :mod:`fempm.implicit.fbar`).

    Raises:
        ValueError: An unknown name or a value out of range, naming the option.
        TypeError: A number option given something else.
    """

    scheme: SchemeName | Scheme = "MUSL"
    flip: float = 1.0
    transfer: Literal["flip", "pic", "apic", "tpic", "xpic"] = "flip"
    xpic_order: int = 2
    affine_cutoff: float | None = None
    mass: str = "lumped"
    cfl: float = 0.4
    mass_cutoff: float = 1e-9
    position: Literal["grid", "particle"] = "grid"
    lumped_forces: bool = False
    lump_below: float = 0.1
    domain: str = "point"
    gimp_order: int | None = None
    gimp_deform: bool = False
    petsc_options_prefix: str = "fempm_step_"
    damping: float = 0.0
    fmpm_order: int | None = None
    integrator: Literal["explicit", "implicit"] = "explicit"
    dynamics: Literal["newmark", "quasi-static"] = "newmark"
    newmark_beta: float = 0.25
    newmark_gamma: float = 0.5
    tangent: Literal["analytic", "finite-difference"] = "analytic"
    max_cuts: int = 6
    load_ramp: float | None = None
    volumetric: Literal["standard", "fbar"] = "standard"

    def _affine_share(self) -> float:
        """The ``affine_cutoff`` in force (see the class)."""
        given = self.affine_cutoff
        if given is None:
            return AFFINE_CUTOFF if self.velocity_transfer.affine and self.integration is None else 0.0
        if not 0.0 <= given < 1.0:
            raise ValueError(f"affine_cutoff={given} must lie in [0, 1): a fraction of the largest nodal mass")
        if given and not self.velocity_transfer.affine:
            raise ValueError(f"affine_cutoff={given} applies to transfer='apic' or 'tpic', not "
                             f"{self.velocity_transfer.name!r}")
        if given and self.integration is not None:
            raise ValueError("the implicit step takes no affine_cutoff (an explicit step's bound of the weak nodes' "
                             "feedback): give affine_cutoff=0")
        return float(given)

    def __post_init__(self):
        check_numbers(self)
        #: the options parsed once into objects: the stages' order, the grid mass, the particle domain
        self.stages = scheme(self.scheme)
        self.mass_model = mass_model(self.mass, self.fmpm_order)
        if self.position not in ("grid", "particle"):
            raise ValueError(f"unknown option position={self.position!r}; expected grid or particle")
        #: whether the particles move with their own updated velocities (position="particle")
        self.particle_position = self.position == "particle"
        if not 0.0 <= self.flip <= 1.0:
            raise ValueError(f"flip={self.flip} must lie in [0, 1]")
        #: the velocity transfer (:mod:`fempm.transfer.transfers`)
        self.velocity_transfer = velocity_transfer(self.transfer, self.flip, self.xpic_order)
        self.particle_domain = step_domain(self.domain, self.gimp_order, self.gimp_deform)
        if self.integrator not in ("explicit", "implicit"):
            raise ValueError(f"unknown option integrator={self.integrator!r}; expected explicit or implicit")
        #: the implicit step's time integration (None: explicit)
        self.integration = (time_integration(self.dynamics, self.newmark_beta, self.newmark_gamma)
                            if self.integrator == "implicit" else None)
        if self.integration is not None and isinstance(self.mass_model, FMPM):
            raise ValueError("the implicit step takes lumped or consistent mass, not FMPM (an explicit step's "
                             "approximation of the consistent mass): give mass='consistent'")
        self.affine_share = self._affine_share()
        if self.integration is not None and self.velocity_transfer.name not in ("flip", "pic", "apic"):
            raise ValueError(f"the implicit step takes transfer='flip', 'pic' or 'apic', not {self.transfer!r}")
        if self.integration is not None and self.particle_position:
            raise ValueError("the implicit step moves the particles with the grid's displacement: position='particle' "
                             "does not apply")
        #: the volumetric average of the deformation increments (None: standard)
        self.volumetric_average = volumetric(self.volumetric)
        if self.tangent not in ("analytic", "finite-difference"):
            raise ValueError(f"unknown option tangent={self.tangent!r}; expected analytic or finite-difference")
        #: whether the implicit step takes the laws' tangents by central differences
        self.finite_difference_tangent = self.tangent == "finite-difference"
        if self.load_ramp is not None and not 0.0 < self.load_ramp < float("inf"):
            raise ValueError(f"load_ramp={self.load_ramp} must be a positive time (or None)")
        if self.max_cuts < 0:
            raise ValueError(f"max_cuts={self.max_cuts} must be a number of halvings >= 0")
        if self.particle_domain.tracks_corners and self.particle_position:
            raise ValueError(f"domain={self.domain!r} moves the particle domains' corners with the grid velocity and "
                             "the particle with its domain's centroid: position='particle' would detach them")
        if not self.damping >= 0.0:
            raise ValueError(f"damping={self.damping} must be >= 0")
        if not 0.0 < self.cfl <= 1.0:
            raise ValueError(f"cfl={self.cfl} must lie in (0, 1]: a CFL number above 1 is unstable")
        if not 0.0 <= self.mass_cutoff < 1.0:
            raise ValueError(f"mass_cutoff={self.mass_cutoff} must lie in [0, 1): a fraction of the largest nodal mass")
        if not 0.0 <= self.lump_below < 1.0:
            raise ValueError(f"lump_below={self.lump_below} must lie in [0, 1): a fraction of the largest lumped mass")
        if self.gimp_order is not None and self.gimp_order < 1:
            raise ValueError(f"gimp_order={self.gimp_order} must be a positive number of Gauss points (or None)")
