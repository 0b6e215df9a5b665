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


#: obstacle sweep geometry: centres spread over x in [3, 10] m, alternating this far right / left
#: of the centreline [m]
OBSTACLE_SPAN_M = (3.0, 10.0)
OBSTACLE_OFFSET_M = 0.3
#: influence distance of the sweep [m]: more than any obstacle's distance from any point of the
#: drive (the car starts at (2, -2) m and, at 1 m/s, is near x = 11 m after 1000 steps; 50 m holds
#: for drives of up to about 3,500 steps), so none is ever dropped
OBSTACLE_INFLUENCE_M = 50.0


def p3_obstacles(n: int) -> BenchProblem:
    """P3 with ``n`` static circle obstacles (r = 0.25 m, P3's Gaussian cost), for the per-step
    time against the obstacle count.

    n = 0 is P1 with P3's lane (|y| <= 1.75 m) and no avoidance; n = 1 is P3's obstacle (x = 5 m
    on the centreline); n >= 2 puts the centres at x evenly spread over [3, 10] m, alternately
    ``OBSTACLE_OFFSET_M`` = 0.3 m right and left of the centreline (the first on the right):
    a zig-zag the car passes on one side. Neighbours stay apart (>= 0.7 m between centres for
    n <= 20). ``max_obstacles = n`` and ``influence_m = OBSTACLE_INFLUENCE_M`` (50 m, P3's
    default is 5 m) so every obstacle is in the problem at every step of the drive -- behind the
    car and far ahead included -- and the time measured is that of n obstacle terms. With the
    Gaussian cost the QP keeps its size: the n terms add into the position cost of each
    predicted step, so what grows with n is the work of building them."""
    n = int(n)
    if n < 0:
        raise ValueError(f"the obstacle count must be >= 0, got {n}")
    base = p3()
    if n == 0:
        return replace(base, name="P3-0obs", description="P1 with P3's lane |y| <= 1.75 m, no obstacles",
                       obstacles=(), avoidance=None)
    if n == 1:
        poses = [base.obstacles[0].pose]
    else:
        xs = np.linspace(*OBSTACLE_SPAN_M, n)
        poses = [(float(x), OBSTACLE_OFFSET_M * (1.0 if i % 2 else -1.0), 0.0) for i, x in enumerate(xs)]
    obstacles = tuple(Obstacle(Circle(0.25), pose, name=f"cone{i}") for i, pose in enumerate(poses))
    av = replace(base.avoidance, max_obstacles=n, influence_m=OBSTACLE_INFLUENCE_M)
    return replace(base, name=f"P3-{n}obs", obstacles=obstacles, avoidance=av,
                   description=f"P3 with {n} obstacle(s) with Gaussian cost, lane |y| <= 1.75 m")


PROBLEMS = {"P1": p1, "P2": p2, "P3": p3}
