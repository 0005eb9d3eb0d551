"""Implicit integration: each step solves the grid momentum balance for the nodal displacement
increment with Newton's method (PETSc SNES), the tangent assembled from the particles.

* :mod:`fempm.implicit.nominal`: the particles' nominal stress with respect to the step's start
  and its tangent, from the laws' stresses and tangents (:mod:`fempm.materials.tangent`).
"""

from fempm.implicit.nominal import nominal_stress

__all__ = ["nominal_stress"]
