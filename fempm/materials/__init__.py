"""Constitutive laws, one per module. Each law is a frozen dataclass with

- ``stress(F, L, sigma, dt, rho) -> sigma_new`` vectorized over (n, d, d) arrays (Cauchy stress),
- ``wave_speed(F, rho) -> c`` (n,), the dilatational wave speed for the CFL bound,
- ``energy_density(F) -> W`` (n,) per reference volume (0 where not defined),
- ``history``: names of extra per-particle arrays the law reads and writes (none here).

A user law is any object with these members (see :class:`fempm.materials.base.Material`).
"""

from fempm.materials.base import Material
from fempm.materials.linear_elastic import LinearElastic
from fempm.materials.neo_hookean import NeoHookean
from fempm.materials.newtonian_eos import NewtonianTait

__all__ = ["LinearElastic", "Material", "NeoHookean", "NewtonianTait"]
