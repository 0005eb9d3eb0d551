"""A scene watch that keeps a history (:attr:`fempm.scene.Scene.watch`) and goes into the
checkpoint with the run, so that a resumed run computes its results from the whole history.

A recorder names the attributes that make its state (:attr:`Recorder.state_keys`): plain
numbers and lists of them, the same on every rank (a watch is called collectively and reduces
what it records). :meth:`Recorder.state_dict` gives them as JSON-ready values, which
:func:`fempm.io.checkpoint.write` stores in the manifest; :meth:`Recorder.load_state_dict`
puts them back when the run resumes. A watch that is a plain callable keeps no state a
checkpoint could hold: give it these two methods (or derive it from :class:`Recorder`) when
its results depend on the steps before a restart.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

__all__ = ["Recorder"]


def _plain(value):
    """``value`` with numpy numbers and arrays, tuples and lists as plain JSON values."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


class Recorder:
    """A scene watch with a checkpointable history (see the module). Subclasses set
    :attr:`state_keys` and define ``__call__(solver)``, called after every step (collective)."""

    #: the attributes that make the recorder's state
    state_keys: ClassVar[tuple[str, ...]] = ()

    def __call__(self, solver) -> None:
        raise NotImplementedError

    def start(self, solver) -> None:
        """Called once with the solver before the first step of a run (not of a resumed one,
        which restores the state instead); the default does nothing. Collective."""

    def state_dict(self) -> dict:
        """The state as JSON-ready values (lists of plain numbers)."""
        return {k: _plain(getattr(self, k)) for k in self.state_keys}

    def load_state_dict(self, state: dict) -> None:
        """Restore :meth:`state_dict` (sequences come back as lists; a list of pairs as tuples).

        Raises:
            ValueError: A state that lacks one of :attr:`state_keys`.
        """
        missing = [k for k in self.state_keys if k not in state]
        if missing:
            raise ValueError(f"the checkpoint's state of {type(self).__name__} lacks {', '.join(missing)}")
        for k in self.state_keys:
            v = state[k]
            if isinstance(v, list):
                v = [tuple(x) if isinstance(x, list) else x for x in v]
            setattr(self, k, v)
