r"""The error-vs-time study's static problems (:mod:`fempm.studies.error_vs_time`): scenes
whose error is a quantity of their end state, run explicitly and implicitly.

* ``cook``: Cook's membrane (:func:`fempm.scenes.cook.cook_membrane`, nu = 1/3, load 1e-3),
  ``cells`` triangles across its 48 wide panel (size :math:`h = 48 / \text{cells}`); error
  :math:`|u_y(C) / (\text{load}\ u_{ref}) - 1|` against the Taylor-Hood reference
  :data:`COOK_REFERENCE`; the explicit run is the scene's damped one to rest, the implicit one
  quasi-static in ``Config.steps`` load steps.
* ``compaction``: the elastic column under its own weight (:func:`fempm.scenes.compaction.compaction`,
  quasi-static implicit in ``Config.steps`` steps; it has no explicit run to rest), ``cells``
  cells over its height; error its ``stress_error``.

Each case returns ``error``, ``wall_s`` (the whole run, the slowest rank), ``status`` and
``mesh``; a failure is raised to the study, which makes it a row.
"""

from __future__ import annotations

import dataclasses
import time

from mpi4py import MPI

from fempm.scene.loop import run as run_scene
from fempm.scenes.compaction import compaction
from fempm.scenes.cook import FE_REFERENCE, cook_membrane
from fempm.studies.convergence import Config

__all__ = ["COOK_LOAD", "COOK_REFERENCE", "COOK_WIDTH", "PROBLEMS", "compaction_case", "cook_case"]

#: u_y(C) per unit load at nu = 1/3, converged (:data:`fempm.scenes.cook.FE_REFERENCE`)
COOK_REFERENCE = FE_REFERENCE[1 / 3]
COOK_LOAD = 1e-3
COOK_WIDTH = 48.0


def _timed(scene, comm) -> tuple[dict, float]:
    """The run's summary and its wall time (the slowest rank)."""
    t0 = time.perf_counter()
    summary = run_scene(scene, None, progress=False)
    return summary, comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)


def cook_case(config: Config, cells: int, comm: MPI.Comm) -> dict:
    """Cook's membrane with ``cells`` triangles across (see the module)."""
    scene = cook_membrane(h=COOK_WIDTH / cells, nu=1 / 3, load=COOK_LOAD, mass=config.mass, domain=config.domain,
                          scheme=config.scheme, frames=0, comm=comm)
    if config.integrator == "quasi-static":
        scene.options = dataclasses.replace(scene.options, integrator="implicit", dynamics="quasi-static",
                                            load_ramp=scene.t_end)
        scene.dt = scene.t_end / config.steps
    elif config.integrator != "explicit":
        raise ValueError(f"cook runs explicit or quasi-static, not {config.integrator!r}")
    summary, wall = _timed(scene, comm)
    uy = summary["corner_displacement"][1] / COOK_LOAD
    return {"error": abs(uy / COOK_REFERENCE - 1.0), "wall_s": wall, "status": "ok", "mesh": "unstructured"}


def compaction_case(config: Config, cells: int, comm: MPI.Comm) -> dict:
    """The compaction column with ``cells`` cells over its height (see the module)."""
    if config.integrator != "quasi-static":
        raise ValueError(f"compaction runs quasi-static, not {config.integrator!r}")
    scene = compaction(cells=cells, ppc=config.ppc or 4, domain=config.domain, mass=config.mass, steps=config.steps,
                       frames=0, comm=comm)
    summary, wall = _timed(scene, comm)
    return {"error": summary["stress_error"], "wall_s": wall, "status": "ok", "mesh": "structured"}


#: the static problems by name
PROBLEMS = {"cook": cook_case, "compaction": compaction_case}
