"""The controller interface the simulator drives."""

from __future__ import annotations

import math
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


def check_state(x, state_names: tuple[str, ...]) -> np.ndarray:
    """``x`` as a float array of one value per state; a ValueError naming the bad fields otherwise."""
    x = np.asarray(x, dtype=float)
    n = len(state_names)
    if x.shape != (n,):
        raise ValueError(f"state must have shape ({n},) {state_names}, got {x.shape}")
    bad = [name for name, v in zip(state_names, x) if not math.isfinite(v)]
    if bad:
        raise ValueError(f"state field(s) {', '.join(bad)} not finite: {dict(zip(state_names, x.tolist()))}")
    return x
