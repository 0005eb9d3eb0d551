"""Implicit integration: each step solves the grid momentum balance for the nodal displacement
increment with Newton's method (PETSc SNES), the tangent assembled from the particles.

* :mod:`fempm.implicit.nominal`: the particles' nominal stress with respect to the step's start
  and its tangent, from the laws' stresses and tangents (:mod:`fempm.materials.tangent`).
* :mod:`fempm.implicit.operator`: an increment's action on the particles, the tangent's blocks.
* :mod:`fempm.implicit.fbar`: the same with F-bar's patch-averaged volume change, and the
  tangent's coupling over the patches.
* :mod:`fempm.implicit.newton`, :mod:`fempm.implicit.step`: Newton on SNES, the step, which
  this package registers as the solver's (:func:`fempm.stepping.solver.register_implicit_step`).
"""

from fempm.implicit.nominal import nominal_stress
from fempm.implicit.step import ImplicitStep
from fempm.stepping.solver import register_implicit_step

register_implicit_step(ImplicitStep)  # the solver's implicit step (fempm.stepping does not import this package)

__all__ = ["ImplicitStep", "nominal_stress"]
