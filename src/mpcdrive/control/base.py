"""The controller interface the simulator drives."""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..types import ControlOutput, WarmStart


class Controller(Protocol):
    """A feedback controller ``u = step(x, warm)``.

    ``initial_warm(x0)`` gives the warm start of the first step; each ``step`` returns a
    :class:`ControlOutput` whose ``warm`` is passed to the next call (no hidden state).
    """

    nx: int
    nu: int
    N: int

    def initial_warm(self, x0: np.ndarray) -> WarmStart: ...

    def step(self, x: np.ndarray, warm: WarmStart) -> ControlOutput: ...
