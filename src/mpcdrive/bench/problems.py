"""The benchmark problems of PERF.md, defined once for every implementation."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..control.mpc import LtvMpc, MpcConfig
from ..ocp.avoidance import AvoidanceConfig
from ..scene import Circle, Footprint, Obstacle
from ..models.kinematic import KinematicBicycle3, KinematicBicycle4
from ..ocp.problem import MpcProblem
from ..paths import CirclePath, Path, StraightPath


@dataclass(frozen=True)
class BenchProblem:
    """A closed loop to time: model, path, problem, config and start state."""

    name: str
    description: str
    model: object
    path: Path
    problem: MpcProblem
    config: MpcConfig
    x0: np.ndarray
    dt_s: float = 0.01
    obstacles: tuple = ()
    avoidance: AvoidanceConfig | None = None
    footprint: Footprint = Footprint()

    def controller(self, **config_changes) -> LtvMpc:
        """mpcdrive's controller for this problem (config fields may be overridden)."""
        cfg = replace(self.config, **config_changes) if config_changes else self.config
        return LtvMpc(self.model, self.path, self.problem, cfg, obstacles=self.obstacles,
                      avoidance=self.avoidance, footprint=self.footprint)


def p1(N: int = 30) -> BenchProblem:
    """P1: straight line, kinematic bicycle 3 states / 1 input, v = 1 m/s, N = 30, Q = I3, R = 1,
    |delta| <= 60 deg (the paper's Experiment 2); ``N`` other than 30 for the horizon sweep."""
    model = KinematicBicycle3(1.0)
    steer = math.radians(60.0)
    pb = MpcProblem(3, 1, N, 0.01, Q=np.ones(3), R=1.0, u_min=-steer, u_max=steer)
    return BenchProblem("P1" if N == 30 else f"P1-N{N}", f"straight line, 3 states / 1 input, N = {N}", model,
                        StraightPath([1.0, 0.0], [11.0, 0.0]), pb, MpcConfig(v_ref_mps=1.0),
                        np.array([2.0, -2.0, math.pi / 2]))


def p2() -> BenchProblem:
    """P2: circle r = 1.5 m with speed, 4 states / 2 inputs, Q = diag(20, 20, 20, 30),
    R = 0.01 I, N = 30, v in [0, 2] m/s (the paper's Experiment 4)."""
    model = KinematicBicycle4()
    steer = math.radians(60.0)
    pb = MpcProblem(4, 2, 30, 0.01, Q=[20.0, 20.0, 20.0, 30.0], R=0.01,
                    u_min=[-steer, -np.inf], u_max=[steer, np.inf],
                    x_min=[-np.inf, -np.inf, -np.inf, 0.0], x_max=[np.inf, np.inf, np.inf, 2.0])
    return BenchProblem("P2", "circle r = 1.5 m with speed, 4 states / 2 inputs, N = 30", model,
                        CirclePath(radius_m=1.5), pb, MpcConfig(v_ref_mps=1.0),
                        np.array([0.0, 1.6, math.pi, 1.0]))


def p3() -> BenchProblem:
    """P3: P1 plus a static obstacle (r = 0.25 m) on the path at x = 5 m with the Gaussian cost
    of eq. 56 (sigma = 0.5 m, weight 10) and lane bounds |y| <= 1.75 m; the non-convex cost is
    kept (sequential QP), not linearized away."""
    base = p1()
    pb = replace(base.problem, lane_half_width_m=1.75)
    obstacle = Obstacle(Circle(0.25), (5.0, 0.0, 0.0), name="cone")
    av = AvoidanceConfig("gaussian", weight=10.0, sigma_m=(0.5, 0.5))
    return BenchProblem("P3", "P1 + obstacle with Gaussian cost, lane |y| <= 1.75 m", base.model,
                        StraightPath([1.0, 0.0], [11.0, 0.0]), pb, base.config, base.x0,
                        obstacles=(obstacle,), avoidance=av)


PROBLEMS = {"P1": p1, "P2": p2, "P3": p3}
