"""The controller interface the simulator drives."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Protocol, TypeVar

import numpy as np

from ..models.base import VehicleModel
from ..ocp.problem import MpcProblem
from ..paths.base import ReferencePath
from ..scene.footprint import Footprint
from ..scene.obstacles import Obstacle
from ..scene.road import Road
from ..scene.world import Scene
from ..types import ControlOutput, WarmStart

A = TypeVar("A")


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


class TrackingWarmStart:
    """Warm start and state check shared by the path-tracking MPC controllers (needs ``model``,
    ``path`` and ``nu`` on the instance)."""

    model: VehicleModel
    path: ReferencePath
    nu: int

    def initial_warm(self, x0) -> WarmStart:
        """Warm start of the first step: a global projection of x0, zero previous input."""
        x0 = self._check_state(x0)
        s0, _ = self.path.project(x0[:2])
        return WarmStart(s_m=float(s0), u_prev=np.zeros(self.nu))

    def _check_state(self, x) -> np.ndarray:
        return check_state(x, tuple(self.model.state_names))

    def _check_warm(self, warm: WarmStart) -> np.ndarray:
        """``warm.u_prev`` as a float array, after checking it and ``warm.s_m``."""
        u_prev = np.asarray(warm.u_prev, dtype=float)
        if u_prev.shape != (self.nu,) or not np.all(np.isfinite(u_prev)):
            raise ValueError(
                f"warm.u_prev must be {self.nu} finite numbers {self.model.input_names}, got {warm.u_prev!r}"
            )
        if not math.isfinite(warm.s_m):
            raise ValueError(f"warm.s_m must be finite, got {warm.s_m!r}")
        return u_prev


def resolve_scene(
    problem: MpcProblem, scene: Scene | None, obstacles, footprint: Footprint | None
) -> tuple[MpcProblem, Scene]:
    """``(problem, scene)`` of an MPC built with ``scene`` (the road, obstacles and body, given
    once) or, the older way, with the road in ``problem.road`` and ``obstacles`` / ``footprint``
    as arguments (their scene is made of them). With a scene, ``problem.road`` becomes the
    scene's road; a ValueError when a part is given twice and differs."""
    if scene is None:
        fp = Footprint() if footprint is None else footprint
        return problem, Scene(problem.road, tuple(obstacles), fp)
    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be a mpcdrive.scene.Scene, got {type(scene).__name__}")
    if tuple(obstacles):
        raise ValueError("obstacles given both in the scene and as obstacles=: give them once, in the scene")
    if footprint is not None and scene.differences(Scene(scene.road, scene.obstacles, footprint)):
        raise ValueError("footprint given both in the scene and as footprint=, and they differ: give it once")
    if problem.road is not None and problem.road is not scene.road:
        if scene.differences(Scene(problem.road, scene.obstacles, scene.footprint)):
            raise ValueError("MpcProblem.road is not the scene's road: give the road once, in the scene")
    elif problem.road is None and scene.road is not None:
        problem = replace(problem, road=scene.road)
    return problem, scene


def projection_guess(warm: WarmStart) -> float:
    """Where [m] to look for the car on the path at the step that receives ``warm``: the arc
    length it had at the step before advanced by what that step's plan drove in a control period
    (the distance between its first two states). The projection searches a window of a few metres
    around it: a car at 28 m/s with a 0.2 s period moves 5.6 m a step, out of reach of a window
    around where it was. Without a plan (the first step) the arc length itself."""
    X = warm.X
    if X is None or len(X) < 2:
        return float(warm.s_m)
    return float(warm.s_m) + math.hypot(float(X[1, 0] - X[0, 0]), float(X[1, 1] - X[0, 1]))


def checked_road(current: Road | None, road: Road) -> Road:
    """``road`` for a ``set_road`` call: a ValueError when the controller was built without a
    road (its QP has no road rows) or ``road`` is not a Road with the same knots."""
    if current is None:
        raise ValueError(
            "this controller was built without a road, so its QP has no road rows: build it with MpcProblem(road=...)"
        )
    if not isinstance(road, Road):
        raise ValueError(f"road must be a mpcdrive.scene.road.Road, got {type(road).__name__}")
    if road.s_m.shape != current.s_m.shape or road.period_m != current.period_m:
        raise ValueError("a new road must have the knots (and period) of the controller's road")
    return road


def checked_speed_cap(v_mps, decel_mps2, default_decel_mps2: float) -> tuple[float, float] | None:
    """``(cap [m/s], decel [m/s^2])`` of a ``set_speed_cap`` call (None: no cap); a ValueError
    for a cap that is not a finite number >= 0 or a deceleration that is not > 0."""
    if v_mps is None:
        return None
    decel = default_decel_mps2 if decel_mps2 is None else decel_mps2
    if not (isinstance(v_mps, (int, float)) and math.isfinite(v_mps) and v_mps >= 0):
        raise ValueError(f"the speed cap must be None or a finite number >= 0 [m/s], got {v_mps!r}")
    if not (isinstance(decel, (int, float)) and math.isfinite(decel) and decel > 0):
        raise ValueError(f"the braking to the speed cap must be a positive number [m/s^2], got {decel!r}")
    return float(v_mps), float(decel)


def checked_plan(s_m, v_mps, N: int) -> tuple[np.ndarray, np.ndarray] | None:
    """``(s (N+1,) [m], v (N+1,) [m/s])`` of a ``set_longitudinal_plan`` call (None: none), copies;
    a ValueError for arrays of another length, not finite, arc lengths that go back or speeds
    below zero."""
    if s_m is None and v_mps is None:
        return None
    s = np.array(s_m, float).reshape(-1)
    v = np.array(v_mps, float).reshape(-1)
    if s.shape != (N + 1,) or v.shape != (N + 1,):
        raise ValueError(f"a longitudinal plan needs N + 1 = {N + 1} arc lengths and speeds, got {s.size} and {v.size}")
    if not (np.all(np.isfinite(s)) and np.all(np.isfinite(v))):
        raise ValueError("a longitudinal plan's arc lengths and speeds must be finite")
    if np.any(np.diff(s) < -1e-9) or np.any(v < -1e-9):
        raise ValueError("a longitudinal plan must not drive backwards (arc lengths non-decreasing, speeds >= 0)")
    return s, np.maximum(v, 0.0)


def plan_arc_lengths(plan_s: np.ndarray, s0_m: float, out: np.ndarray | None = None) -> np.ndarray:
    """The arc lengths [m] of a checked plan's ``plan_s`` (N+1,), moved to start at the car's arc
    length ``s0_m`` [m] (the plan keeps its distances, the path's projection of the car its
    start), into ``out`` (N+1,) if given."""
    out = np.subtract(plan_s, plan_s[0], out=out)
    out += s0_m
    return out


def checked_obstacles(avoidance: A | None, obstacles) -> tuple[A, tuple[Obstacle, ...]]:
    """``(avoidance, obstacles)`` of a ``set_obstacles`` call, the obstacles as a tuple of
    :class:`Obstacle`; a ValueError for a controller built without obstacles (``avoidance`` None:
    its QP has no obstacle terms) or for an item that is not an Obstacle."""
    if avoidance is None:
        raise ValueError(
            "this controller was built without obstacles, so its QP has no obstacle "
            "terms: pass obstacles (and avoidance) at construction"
        )
    obstacles = tuple(obstacles)
    for j, ob in enumerate(obstacles):
        if not isinstance(ob, Obstacle):
            raise ValueError(f"obstacles[{j}] must be an Obstacle, got {type(ob).__name__}")
    return avoidance, obstacles
