"""A maneuver planner's relations to the obstacles, as the hard rows keep them.

The planner (:mod:`mpcdrive.planning`) labels each obstacle at each step of its maneuver: the
car is clear of it, behind it, ahead of it, or beside it on its left / right. Handed to the
controller (:meth:`~mpcdrive.ocp.avoidance.Avoidance.set_relations`), the rows of that obstacle
keep the relation at that step -- a stop row, a keep-ahead row, a lateral row on that side, the
nearest-point half-plane -- so that the safety net agrees with the maneuver; the obstacles it
does not name are decided as without a planner (:func:`step_modes`).
"""

from __future__ import annotations

import numpy as np

from . import avoidance_compiled as _ac

__all__ = ["REL_AHEAD", "REL_BEHIND", "REL_CLEAR", "REL_LEFT", "REL_RIGHT", "checked_relations", "step_modes"]

#: the car is clear of the obstacle, behind it, ahead of it, beside it on its left / right
REL_CLEAR, REL_BEHIND, REL_AHEAD, REL_LEFT, REL_RIGHT = 0, 1, 2, 3, 4
#: the rows of each relation: the passing side (a lateral row on SIDE_LEFT / SIDE_RIGHT) and the mode
_REL_SIDE = np.array([_ac.SIDE_NONE, _ac.SIDE_BLOCKED, _ac.SIDE_NONE, _ac.SIDE_LEFT, _ac.SIDE_RIGHT], np.int64)
_REL_MODE = np.array([_ac.MODE_AVOID, _ac.MODE_STOP, _ac.MODE_AHEAD, _ac.MODE_AVOID, _ac.MODE_AVOID], np.int64)


def checked_relations(relations: dict | None, N: int) -> dict[int, np.ndarray]:
    """``relations`` (obstacle index -> (N,) ``REL_*`` codes of steps 1..N) as int arrays; a
    ValueError for codes of another length or outside ``REL_*``."""
    out: dict[int, np.ndarray] = {}
    for j, codes in (relations or {}).items():
        c = np.asarray(codes, np.int64)
        if c.shape != (N,):
            raise ValueError(f"relations of obstacle {j}: {N} codes (steps 1..N) needed, got {c.shape}")
        out[int(j)] = c
    if out:  # the codes checked all at once (a planner names a few hundred obstacles a step)
        c = np.stack(list(out.values()))
        bad = np.flatnonzero(np.any((c < REL_CLEAR) | (c > REL_RIGHT), axis=1))
        if len(bad):
            j = list(out)[int(bad[0])]
            raise ValueError(f"relations of obstacle {j}: codes must be REL_* ({REL_CLEAR}..{REL_RIGHT})")
    return out


def step_modes(rel, sides, following, ahead, relations: dict[int, np.ndarray], N: int) -> tuple[np.ndarray, np.ndarray]:
    """(side (n, N), mode (n, N)) of the obstacles ``rel`` at steps 1..N: from the planner's
    ``relations`` where they name the obstacle, else the step's own decisions (``sides``, the
    cars ``following``, the obstacles a stop line may go ``ahead`` of) for every step: a stop row
    before an obstacle blocking the way ahead, a keep-ahead row for a car following."""
    n = len(rel)
    side = np.empty((n, N), np.int64)
    mode = np.empty((n, N), np.int64)
    for i, j in enumerate(rel):
        codes = relations.get(j)
        if codes is not None:
            side[i] = _REL_SIDE[codes]
            mode[i] = _REL_MODE[codes]
            continue
        side[i] = sides[j]
        if sides[j] == _ac.SIDE_BLOCKED and ahead[j]:
            mode[i] = _ac.MODE_STOP
        elif j in following:
            mode[i] = _ac.MODE_AHEAD
        else:
            mode[i] = _ac.MODE_AVOID
    return side, mode
