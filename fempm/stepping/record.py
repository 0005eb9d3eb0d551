"""What the steps report over a run: :class:`StepRecord`, kept by the solver, written by its
grid and the implicit step, its running entries carried on by a continued run."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

__all__ = ["StepRecord"]


@dataclass
class StepRecord:
    r"""What the steps report, kept by the solver and written by its grid.

    Attributes:
        terms: how often each force term was assembled.
        j_range: the global (min, max) of J after the last step (None before the first).
        mass_ratio: the last estimate of :math:`\lambda_{min}(M_L^{-1} M_C)` (consistent mass).
        extended_steps: steps whose particle domains reached beyond this rank's ghost cells.
        newton_iterations: the Newton iterations of the implicit steps so far.
        cut_steps: how often an implicit step that did not converge was halved.
        load_work: the work of the external loads in the last implicit step, the trapezoidal
            rule over its nodal displacement increments (:mod:`fempm.implicit.step`).
        load_impulse: the impulse of the external loads in the last implicit step (d,).
        reaction: the momentum the grid conditions took in the last step on this rank (d,;
            explicit: empty without conditions on given nodes, :mod:`fempm.stepping.reactions`;
            implicit: the held components', with Newmark's method).
        damping_impulse: the impulse of the grid damping in the last explicit step on this rank
            (d,; empty without damping).
    """

    terms: Counter = field(default_factory=Counter)
    j_range: tuple[float, float] | None = None
    mass_ratio: float = 1.0
    extended_steps: int = 0
    newton_iterations: int = 0
    cut_steps: int = 0
    load_work: float = 0.0
    load_impulse: npt.NDArray = field(default_factory=lambda: np.zeros(0))
    reaction: npt.NDArray = field(default_factory=lambda: np.zeros(0))
    damping_impulse: npt.NDArray = field(default_factory=lambda: np.zeros(0))

    #: the entries a continued run carries on (the others are the last step's)
    KEPT = ("terms", "j_range", "mass_ratio", "extended_steps", "newton_iterations", "cut_steps")

    def state_dict(self) -> dict:
        """The entries of :attr:`KEPT` (JSON values)."""
        return {"terms": dict(self.terms), "j_range": list(self.j_range) if self.j_range is not None else None,
                "mass_ratio": self.mass_ratio, "extended_steps": self.extended_steps,
                "newton_iterations": self.newton_iterations, "cut_steps": self.cut_steps}

    def load_state_dict(self, state: dict) -> None:
        """Restore :meth:`state_dict` (an entry it lacks keeps its value)."""
        self.terms = Counter(state.get("terms", self.terms))
        if "j_range" in state:
            self.j_range = tuple(state["j_range"]) if state["j_range"] is not None else None
        self.mass_ratio = float(state.get("mass_ratio", self.mass_ratio))
        for k in ("extended_steps", "newton_iterations", "cut_steps"):
            setattr(self, k, int(state.get(k, getattr(self, k))))
