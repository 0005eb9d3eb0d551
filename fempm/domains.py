"""Particle domains (:mod:`fempm.transfer.domains`); this path stays for the code that imports it."""

from fempm.particles.corners import box_corners, corner_signs, domain_geometry
from fempm.transfer.domains import (
    CPDI1,
    CPDI2,
    DOMAINS,
    GIMP,
    GIMP_NAMES,
    Point,
    Samples,
    half_widths,
    make_domain,
)

__all__ = [
    "box_corners",
    "corner_signs",
    "domain_geometry",
    "Samples",
    "half_widths",
    "Point",
    "GIMP",
    "CPDI1",
    "CPDI2",
    "DOMAINS",
    "GIMP_NAMES",
    "make_domain",
]
