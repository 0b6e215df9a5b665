"""A controller that sees the other cars' predictions instead of their futures.

:class:`PredictingController` wraps a controller that avoids obstacles (``set_obstacles``). It
holds the obstacles as they really move (given at construction, e.g. recorded trajectories,
and replaced by ``set_obstacles``, e.g. each step's traffic of a co-simulation) and, before
every step, hands the controller only what is observable then: static obstacles as they are,
every moving one observed at the step's time (:func:`~.predictor.observe`) and predicted
(:meth:`~.predictor.LanePredictor.predict`). The order is fixed (obstacle ``i``'s bands at
``i * bands ...``), so an index keeps naming the same prediction from step to step.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any

import numpy as np

from ..control.base import Controller
from ..scene.obstacles import Obstacle
from ..types import ControlOutput, WarmStart
from .predictor import LanePredictor, observe


class PredictingController:
    """``inner`` driving among ``obstacles`` it knows only through ``predictor``.

    target : the object whose ``set_obstacles`` receives the predictions (default ``inner``; the
    MPC under the maneuver planner or a state adapter); period_s : the control period [s] (the
    velocity of a recorded obstacle is its displacement over it). The step's ``solve_time_s``
    includes the prediction.
    """

    def __init__(self, inner: Controller, predictor: LanePredictor, obstacles=(), *, period_s: float, target=None):
        self.inner = inner
        self.predictor = predictor
        self.period_s = float(period_s)
        self.target: Any = inner if target is None else target
        if not callable(getattr(self.target, "set_obstacles", None)):
            raise ValueError("the predicting controller needs a controller that takes obstacles (set_obstacles)")
        self.nx, self.nu, self.N = inner.nx, inner.nu, inner.N
        self.name = getattr(inner, "name", type(inner).__name__)
        self.truth: tuple[Obstacle, ...] = tuple(obstacles)
        #: the obstacles handed to the controller at the last step
        self.predicted: tuple[Obstacle, ...] = ()

    def __getattr__(self, name):  # the inner controller's attributes (problem, dt_s, path ...)
        if name in ("inner", "target"):
            raise AttributeError(name)
        return getattr(self.inner, name)

    def set_obstacles(self, obstacles) -> None:
        """The obstacles as they are (moving ones' motions are not handed on: only their
        observation at each step is)."""
        obstacles = tuple(obstacles)
        for j, ob in enumerate(obstacles):
            if not isinstance(ob, Obstacle):
                raise ValueError(f"obstacles[{j}] must be an Obstacle, got {type(ob).__name__}")
        self.truth = obstacles

    def initial_warm(self, x0) -> WarmStart:
        return self.inner.initial_warm(x0)

    def predictions(self, t_s: float, ego_xy=None) -> tuple[Obstacle, ...]:
        """What the controller gets at ``t_s`` [s]: static obstacles as they are, each moving one
        as :attr:`predictor`'s bands (absent bands where the obstacle is not there now, or farther
        than the predictor's ``range_m`` from ``ego_xy`` (x m, y m) when given)."""
        out: list[Obstacle] = []
        nb = self.predictor.bands
        reach = self.predictor.config.range_m
        for ob in self.truth:
            if not ob.moving:
                out.append(ob)
                continue
            obs = observe(ob, t_s, self.period_s)
            if obs is not None and ego_xy is not None:
                if math.hypot(obs.pose[0] - ego_xy[0], obs.pose[1] - ego_xy[1]) > reach:
                    obs = None
            if obs is None:  # not seen now: its bands are absent (same count, same indices)
                out += [
                    Obstacle(ob.shape, ob.pose, name=f"{ob.name}~{k}", t_start_s=-np.inf, t_end_s=-np.inf)
                    for k in range(nb)
                ]
            else:
                out += self.predictor.predict(obs)
        return tuple(out)

    def step(self, x, warm: WarmStart) -> ControlOutput:
        t0 = time.perf_counter()
        x = np.asarray(x, float)
        self.predicted = self.predictions(float(warm.t_s), (float(x[0]), float(x[1])))
        self.target.set_obstacles(self.predicted)
        out = self.inner.step(x, warm)
        return dataclasses.replace(out, solve_time_s=time.perf_counter() - t0)
