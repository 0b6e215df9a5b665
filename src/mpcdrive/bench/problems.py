"""The benchmark problems P1-P4 (docs/benchmarks.md), defined once for every implementation."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..control.mpc import LtvMpc, MpcConfig
from ..ocp.avoidance import AvoidanceConfig
from ..scene import Circle, Footprint, Obstacle
from ..scene.road import Road
from ..scene.obstacles import ConstantVelocity, rectangle
from ..models.kinematic import KinematicBicycle3, KinematicBicycle4, KinematicParams
from ..models.presets import get_preset
from ..ocp.problem import MpcProblem
from ..paths import CirclePath, ReferencePath, StraightPath


@dataclass(frozen=True)
class BenchProblem:
    """A closed loop to time: model, path, problem, config and start state."""

    name: str
    description: str
    model: object
    path: ReferencePath
    problem: MpcProblem
    config: MpcConfig
    x0: np.ndarray
    dt_s: float = 0.01
    obstacles: tuple = ()
    avoidance: AvoidanceConfig | None = None
    footprint: Footprint = Footprint()
    #: the problem's own closed-loop length (P4), else None: as many steps as asked
    steps: int | None = None

    def controller(self, solver: str = "osqp", assembly: str = "python", **config_changes) -> LtvMpc:
        """mpcdrive's controller for this problem (config fields may be overridden); by default
        the reference: the stage QP assembled in Python, solved by OSQP (the baselines take its
        ``prepare``)."""
        cfg = replace(self.config, **config_changes) if config_changes else self.config
        return LtvMpc(
            self.model,
            self.path,
            self.problem,
            cfg,
            solver,  # type: ignore[arg-type]
            obstacles=self.obstacles,
            avoidance=self.avoidance,
            footprint=self.footprint,
            assembly=assembly,  # type: ignore[arg-type]
        )


def p1(N: int = 30) -> BenchProblem:
    """P1: straight line, kinematic bicycle 3 states / 1 input, v = 1 m/s, N = 30, Q = I3, R = 1,
    |delta| <= 60 deg (the paper's Experiment 2); ``N`` other than 30 for the horizon sweep."""
    model = KinematicBicycle3(1.0)
    steer = math.radians(60.0)
    pb = MpcProblem(3, 1, N, 0.01, Q=np.ones(3), R=1.0, u_min=-steer, u_max=steer)
    return BenchProblem(
        "P1" if N == 30 else f"P1-N{N}",
        f"straight line, 3 states / 1 input, N = {N}",
        model,
        StraightPath([1.0, 0.0], [11.0, 0.0]),
        pb,
        MpcConfig(v_ref_mps=1.0),
        np.array([2.0, -2.0, math.pi / 2]),
    )


def p2() -> BenchProblem:
    """P2: circle r = 1.5 m with speed, 4 states / 2 inputs, Q = diag(20, 20, 20, 30),
    R = 0.01 I, N = 30, v in [0, 2] m/s (the paper's Experiment 4)."""
    model = KinematicBicycle4()
    steer = math.radians(60.0)
    pb = MpcProblem(
        4,
        2,
        30,
        0.01,
        Q=[20.0, 20.0, 20.0, 30.0],
        R=0.01,
        u_min=[-steer, -np.inf],
        u_max=[steer, np.inf],
        x_min=[-np.inf, -np.inf, -np.inf, 0.0],
        x_max=[np.inf, np.inf, np.inf, 2.0],
    )
    return BenchProblem(
        "P2",
        "circle r = 1.5 m with speed, 4 states / 2 inputs, N = 30",
        model,
        CirclePath(radius_m=1.5),
        pb,
        MpcConfig(v_ref_mps=1.0),
        np.array([0.0, 1.6, math.pi, 1.0]),
    )


def p3() -> BenchProblem:
    """P3: P1 plus a static obstacle (r = 0.25 m) on the path at x = 5 m with the Gaussian cost
    of eq. 56 (sigma = 0.5 m, weight 10) and lane bounds |y| <= 1.75 m; the non-convex cost is
    kept (sequential QP), not linearized away."""
    base = p1()
    pb = replace(base.problem, road=Road.constant(3.5))
    obstacle = Obstacle(Circle(0.25), (5.0, 0.0, 0.0), name="cone")
    av = AvoidanceConfig("gaussian", weight=10.0, sigma_m=(0.5, 0.5))
    return BenchProblem(
        "P3",
        "P1 + obstacle with Gaussian cost, lane |y| <= 1.75 m",
        base.model,
        StraightPath([1.0, 0.0], [11.0, 0.0]),
        pb,
        base.config,
        base.x0,
        obstacles=(obstacle,),
        avoidance=av,
    )


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
        return replace(
            base,
            name="P3-0obs",
            description="P1 with P3's lane |y| <= 1.75 m, no obstacles",
            obstacles=(),
            avoidance=None,
        )
    if n == 1:
        poses = [base.obstacles[0].pose]
    else:
        xs = np.linspace(*OBSTACLE_SPAN_M, n)
        poses = [(float(x), OBSTACLE_OFFSET_M * (1.0 if i % 2 else -1.0), 0.0) for i, x in enumerate(xs)]
    obstacles = tuple(Obstacle(Circle(0.25), pose, name=f"cone{i}") for i, pose in enumerate(poses))
    av = replace(base.avoidance, max_obstacles=n, influence_m=OBSTACLE_INFLUENCE_M)
    return replace(
        base,
        name=f"P3-{n}obs",
        obstacles=obstacles,
        avoidance=av,
        description=f"P3 with {n} obstacle(s) with Gaussian cost, lane |y| <= 1.75 m",
    )


#: P4 geometry and traffic: lanes [m], road length [m], cars [m], their speed range [m/s], seed
P4_LANE_WIDTH_M = 3.5
P4_ROAD_LENGTH_M = 300.0
P4_CAR_LENGTH_M, P4_CAR_WIDTH_M = 4.5, 1.8
P4_SPEED_RANGE_MPS = (12.0, 25.0)
P4_SEED = 20261201
#: the ego: start [m] on the centre lane and speed [m/s]; the slower car ahead of it: gap between
#: the two centres [m] and speed [m/s]; the other cars of the ego lane: at least this fast [m/s]
P4_EGO_X_M, P4_EGO_SPEED_MPS = 30.0, 20.0
P4_LEAD_GAP_M, P4_LEAD_SPEED_MPS = 45.0, 14.0
P4_AHEAD_MIN_SPEED_MPS = 20.5
#: cars per lane: right (y = -3.5 m), left (y = 3.5 m), ego lane (y = 0, the slower car included)
P4_CARS_PER_LANE = (7, 7, 6)
#: least distance between the centres of two cars in one lane [m] (a 4.5 m car plus 15.5 m)
P4_MIN_HEADWAY_M = 20.0
#: the passing window [s] and the room [m] (centre to centre, along the road) that the left lane
#: leaves around the ego's nominal drive in it
P4_PASS_WINDOW_S = (2.0, 14.0)
P4_PASS_ROOM_M = 25.0


def _p4_lane(rng, n: int, x_from: float, v_range: tuple[float, float]) -> list[tuple[float, float]]:
    """``n`` cars (x [m], v [m/s]) on [x_from, road end]: positions uniform with at least
    P4_MIN_HEADWAY_M between them, speeds uniform in ``v_range`` sorted so that no car is faster
    than the one ahead of it."""
    xs: list[float] = []
    while len(xs) < n:
        x = float(rng.uniform(x_from, P4_ROAD_LENGTH_M))
        if all(abs(x - o) >= P4_MIN_HEADWAY_M for o in xs):
            xs.append(x)
    return list(zip(sorted(xs), np.sort(rng.uniform(*v_range, n)).tolist()))


def _p4_leaves_room(cars: list[tuple[float, float]]) -> bool:
    """No car within P4_PASS_ROOM_M of the ego's nominal drive (20 m/s from its start) during the
    passing window."""
    t = np.linspace(*P4_PASS_WINDOW_S, 61)
    ego = P4_EGO_X_M + P4_EGO_SPEED_MPS * t
    return all(np.all(np.abs(x + v * t - ego) >= P4_PASS_ROOM_M) for x, v in cars)


def p4_traffic(seed: int = P4_SEED) -> tuple[Obstacle, ...]:
    """The 20 cars of P4: 4.5 m x 1.8 m rectangles at constant velocity along +x, drawn with
    ``seed``; lanes centred at y = -3.5 (right), 0 (the ego's) and 3.5 m (left).

    Each lane's cars are spread uniformly over the road (at least ``P4_MIN_HEADWAY_M`` = 20 m
    between centres) at speeds uniform in [12, 25] m/s, sorted so that no car is faster than the
    one ahead of it (the predictions never drive through each other). Right lane: 7 cars. Left
    lane: 7 cars, the lane drawn again until it leaves the ego room to pass (no car within
    ``P4_PASS_ROOM_M`` = 25 m of the ego's nominal 20 m/s drive for t in [2, 14] s). Ego lane:
    the slower car (``lead``) 45 m ahead of the ego at 14 m/s and 5 cars ahead of it at
    20.5-25 m/s, faster than the ego; nothing behind the ego in its lane (a constant-velocity car
    would run into it from behind whatever it did)."""
    rng = np.random.default_rng(seed)
    n_right, n_left, n_ego = P4_CARS_PER_LANE
    right = _p4_lane(rng, n_right, 0.0, P4_SPEED_RANGE_MPS)
    left = _p4_lane(rng, n_left, 0.0, P4_SPEED_RANGE_MPS)
    while not _p4_leaves_room(left):
        left = _p4_lane(rng, n_left, 0.0, P4_SPEED_RANGE_MPS)
    lead_x = P4_EGO_X_M + P4_LEAD_GAP_M
    ahead = _p4_lane(rng, n_ego - 1, lead_x + P4_MIN_HEADWAY_M, (P4_AHEAD_MIN_SPEED_MPS, P4_SPEED_RANGE_MPS[1]))
    shape = rectangle(P4_CAR_LENGTH_M, P4_CAR_WIDTH_M)
    lanes = ((-P4_LANE_WIDTH_M, "right", right), (P4_LANE_WIDTH_M, "left", left), (0.0, "ego-lane", ahead))
    cars = [Obstacle(shape, (lead_x, 0.0, 0.0), ConstantVelocity(P4_LEAD_SPEED_MPS, 0.0), name="lead")]
    for y, lane, entries in lanes:
        cars += [
            Obstacle(shape, (x, y, 0.0), ConstantVelocity(v, 0.0), name=f"{lane}{i}")
            for i, (x, v) in enumerate(entries)
        ]
    return tuple(cars)


def p4() -> BenchProblem:
    """P4: real traffic on a straight three-lane road (300 m, lanes 3.5 m; the road is the three
    lanes, |y| <= 5.25 m about the centre lane the ego tracks), ego the BMW 320i preset
    (``commonroad_bmw_320i``: lf, lr, 4.508 m x 1.61 m, steering +-1.066 rad at up to 0.4 rad/s)
    on the kinematic bicycle with speed state (``kinematic4``) at 20 m/s, dt = 0.1 s, N = 30,
    Q = diag(1, 1, 2, 1), R = diag(10, 0.1), Rc = diag(100, 1), acceleration in [-6, 3] m/s^2,
    speed in [0, 25] m/s; the 20 cars of :func:`p4_traffic` predicted at constant velocity, hard
    avoidance rows (three discs per body, margin 0.3 m, the 5 nearest cars within 70 m);
    300 closed-loop steps (30 s; the straight road runs on past its 300 m as the traffic does)."""
    pre = get_preset("commonroad_bmw_320i")
    model = KinematicBicycle4(KinematicParams(pre.params.lf_m, pre.params.lr_m))
    dt = 0.1
    pb = MpcProblem(
        4,
        2,
        30,
        dt,
        Q=[1.0, 1.0, 2.0, 1.0],
        R=[10.0, 0.1],
        Rc=[100.0, 1.0],
        u_min=[-pre.max_steer_rad, -6.0],
        u_max=[pre.max_steer_rad, 3.0],
        du_max_per_s=[pre.max_steer_rate_rad_s, np.inf],
        x_min=[-np.inf, -np.inf, -np.inf, 0.0],
        x_max=[np.inf, np.inf, np.inf, 25.0],
        road=Road.constant(3 * P4_LANE_WIDTH_M),
    )
    # the projection window covers the distance driven per step, and more
    cfg = MpcConfig(v_ref_mps=P4_EGO_SPEED_MPS, projection_window_m=3.0 * 25.0 * dt)
    av = AvoidanceConfig("hard", margin_m=0.3, influence_m=70.0, max_obstacles=5)
    return BenchProblem(
        "P4",
        "three-lane road, 20 cars, kinematic4 BMW 320i at 20 m/s, N = 30, dt = 0.1 s",
        model,
        StraightPath([0.0, 0.0], [P4_ROAD_LENGTH_M, 0.0]),
        pb,
        cfg,
        np.array([P4_EGO_X_M, 0.0, 0.0, P4_EGO_SPEED_MPS]),
        dt_s=dt,
        obstacles=p4_traffic(),
        avoidance=av,
        footprint=Footprint(pre.length_m, pre.width_m, n_discs=3),
        steps=300,
    )


PROBLEMS = {"P1": p1, "P2": p2, "P3": p3, "P4": p4}
