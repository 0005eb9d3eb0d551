"""Constitutive laws, one per module. Each law is a frozen dataclass with

- ``stress(F, L, sigma, dt, rho) -> sigma_new`` vectorized over (n, d, d) arrays (Cauchy stress),
  and for a law with internal variables ``stress(F, L, sigma, dt, rho, state)``;
- ``wave_speed(F, rho) -> c`` (n,), the dilatational wave speed for the CFL bound,
- ``energy_density(F) -> W`` (n,) per reference volume (0 where not defined; laws with
  ``energy_from_stress`` take the stress and state too: the elastic part of a plastic law),
- ``history``: the law's internal variables (:class:`fempm.materials.base.Internal`: name,
  shape, initial value), kept by the solver in ``particles.fields``.

Elastic: :class:`LinearElastic`, :class:`NeoHookean`; fluid: :class:`NewtonianTait`;
plastic (hypoelastic, Jaumann rate, plane strain in 2D): :class:`VonMises`,
:class:`DruckerPrager`; granular flow: :class:`MuI` (rate-dependent, explicit only). A user law
is any object with these members (:class:`fempm.materials.base.Material`).
"""

from fempm.materials.base import Internal, Material
from fempm.materials.drucker_prager import DruckerPrager
from fempm.materials.linear_elastic import LinearElastic
from fempm.materials.mu_i import MuI
from fempm.materials.neo_hookean import NeoHookean
from fempm.materials.newtonian_eos import NewtonianTait
from fempm.materials.von_mises import VonMises

__all__ = ["DruckerPrager", "Internal", "LinearElastic", "Material", "MuI", "NeoHookean", "NewtonianTait",
           "VonMises"]
