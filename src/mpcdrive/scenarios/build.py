"""Turn a validated scenario into core objects and run it."""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..control.adapters import StateAdapter
from ..control.base import Controller
from ..control.delay import DelayCompensator
from ..control.fallback import FallbackConfig
from ..control.mpc import LtvMpc, MpcConfig
from ..models.dynamic import DynamicBicycle, DynamicParams
from ..models.kinematic import KinematicBicycle3, KinematicBicycle4, KinematicParams, slip_terms
from ..ocp.problem import MpcProblem
from ..planning import PlannerConfig, PlanningGoal
from ..planning.driver import PlannedMpc
from ..paths import CirclePath, ReferencePath, StraightPath, WaypointPath
from ..paths.speed_profile import SpeedProfile
from ..paths.tracks import Track, load_track_csv, track_from_text
from ..sim.actuator import SteeringActuator
from ..sim.closed_loop import Disturbance, ObservedPlant, Plant, inner_attr, simulate
from ..sim.verdict import VerdictCriteria
from ..ocp.avoidance import AvoidanceConfig
from ..scene.footprint import Footprint
from ..scene.road import Lane, Road
from ..scene.world import Scene
from ..scene.obstacles import Circle, ConstantVelocity, Obstacle, Polygon, Static, TrajectoryMotion, rectangle
from ..solvers.osqp_backend import OsqpSettings
from ..solvers.projected_gradient import ProjectedGradientSettings
from ..types import ScenarioWarning, SimResult
from .schema import COMMONROAD_PLANTS, AvoidanceSpec, NoiseSpec, ObstacleSpec, ScenarioSpec
from .steering import IDEAL_STEERING


@dataclass(frozen=True)
class Experiment:
    """Everything a run needs, built from a scenario."""

    spec: ScenarioSpec
    path: ReferencePath
    controller: Controller
    plant: Plant | ObservedPlant
    x0: np.ndarray
    steps: int
    footprint: Footprint
    disturbance: Disturbance | None
    measurement_noise: Disturbance | None
    obstacles: tuple[Obstacle, ...] = ()
    mpc: LtvMpc | None = None
    track: Track | None = None
    speed_profile: SpeedProfile | None = None
    road: Road | None = None


def load_track(spec) -> Track:
    """The track of a ``csv`` path spec: a packaged track name or a file path."""
    from .tracks import packaged_track_names, packaged_track_text

    if spec.file in packaged_track_names():
        return track_from_text(
            packaged_track_text(spec.file),
            f"track {spec.file}",
            closed=spec.closed,
            smoothing=spec.smoothing,
            name=spec.file,
        )
    return load_track_csv(spec.file, closed=spec.closed, smoothing=spec.smoothing)


def build_path(spec) -> ReferencePath:
    if spec.type == "straight":
        return StraightPath(spec.start, spec.end)
    if spec.type == "circle":
        return CirclePath(spec.center, spec.radius_m, spec.ccw, math.radians(spec.start_angle_deg))
    if spec.type == "csv":
        return load_track(spec).path
    return WaypointPath(
        spec.points, closed=spec.closed, smoothing=spec.smoothing, ds_m=spec.ds_m, interpolation=spec.interpolation
    )


def warn_if_path_too_curved(spec: ScenarioSpec, path: ReferencePath, source: str | None = None) -> float | None:
    """Warn (:class:`~mpcdrive.types.ScenarioWarning`) when the path turns tighter than the
    vehicle can at full steering; returns the worst mean curvature found [1/m], or None when
    the vehicle can follow the whole path.

    The car's tightest turn: its centre of gravity moves on curvature ``sin(beta) / lr`` with the
    slip angle ``tan(beta) = lr / (lf + lr) tan(max_steer)`` (the kinematic bicycle's, which the
    dynamic bicycle becomes at low speed; ``tan(max_steer) / wheelbase`` at the rear axle). The
    path's curvature is its heading change over one wheelbase (a corner's 90 deg over a metre is
    a curvature of 1.57 1/m), the worst such stretch is compared.
    """
    v = spec.vehicle
    lq = v.lr_m / (v.lf_m + v.lr_m)
    _, sin_beta, _ = slip_terms(math.radians(spec.controller.max_steer_deg), lq, np)
    kappa_max = float(sin_beta) / v.lr_m
    window = v.lf_m + v.lr_m
    L = float(path.length_m)
    closed = bool(getattr(path, "closed", False)) or isinstance(path, CirclePath)
    if L <= window and not closed:
        return None
    n = int(math.ceil((L + (window if closed else 0.0)) / (window / 8.0))) + 1
    s = np.linspace(0.0, L + window if closed else L, n)
    h = np.unwrap(np.asarray(path.heading(s), float))
    shift = min(8, n - 1)
    kappa = np.abs(h[shift:] - h[:-shift]) / (s[shift:] - s[:-shift])
    i = int(np.argmax(kappa))
    if kappa[i] <= kappa_max * (1.0 + 1e-6):
        return None
    s_at = 0.5 * (s[i] + s[i + shift]) % L if closed else 0.5 * (s[i] + s[i + shift])
    x, y = np.asarray(path.position(s_at), float)
    where = "path.points" if spec.path.type == "waypoints" else "path"
    warnings.warn(
        f"{source or 'scenario ' + repr(spec.id)}: {where}: the path turns at {kappa[i]:.3g} 1/m (radius "
        f"{1.0 / kappa[i]:.3g} m) over {window:.3g} m around s = {s_at:.4g} m, ({x:.4g}, {y:.4g}) m, tighter than "
        f"the vehicle's {kappa_max:.3g} 1/m (radius {1.0 / kappa_max:.3g} m) at controller.max_steer_deg "
        f"{spec.controller.max_steer_deg:g}: it cannot follow the path there",
        ScenarioWarning,
        stacklevel=2,
    )
    return float(kappa[i])


def path_doubles_back(spec: ScenarioSpec, path: ReferencePath, road: Road | None) -> tuple[str, str] | None:
    """(field, problem) when the path doubles back (:meth:`ReferencePath.doubling_back`) onto
    the band a run is judged in -- the whole road (every lane), at least the body's half width
    either side -- else None. Where: the waypoint nearest the turn (``path.points``), else the
    position (``path.file`` for a track, ``path``)."""
    half_body = 0.5 * spec.vehicle.width_m
    whole = None if road is None else road.whole()
    if whole is None:
        band = half_body
    else:

        def band(s):
            left, right = whole.edges(s)
            return np.maximum(np.maximum(np.abs(left), np.abs(right)), half_body)

    back = path.doubling_back(band)
    if back is None:
        return None
    turn = np.asarray(path.position(0.5 * (back.s_m + back.s_back_m)), float)
    if spec.path.type == "waypoints":
        pts = np.asarray(spec.path.points, float)
        i = int(np.argmin(np.hypot(*(pts - turn).T)))
        field, where = "path.points", f"at point {i} ({pts[i, 0]:.4g}, {pts[i, 1]:.4g}) m"
    else:
        field = "path.file" if spec.path.type == "csv" else "path"
        where = f"at ({turn[0]:.4g}, {turn[1]:.4g}) m"
    return (
        field,
        f"the path doubles back {where}: at s = {back.s_back_m:.4g} m it comes back to {back.distance_m:.3f} m "
        f"from itself at s = {back.s_m:.4g} m, inside the {back.band_m:.3g} m band of road around it, so a "
        "position there has two arc lengths and lateral offsets (lane excess and tracking errors would be "
        "measured from the wrong stretch): split the drive in two or widen the turn",
    )


def build_obstacle(spec: ObstacleSpec) -> Obstacle:
    """Core obstacle from its scenario entry."""
    if spec.shape == "circle":
        shape = Circle(spec.radius_m)
    elif spec.shape == "rectangle":
        shape = rectangle(spec.length_m, spec.width_m)
    else:
        shape = Polygon(np.array(spec.points, float))
    yaw = math.radians(spec.yaw_deg)
    if spec.trajectory is not None:
        tr = spec.trajectory
        pts = np.array(tr.points, float)
        yaws = np.radians(tr.yaw_deg) if tr.yaw_deg is not None else np.full(len(pts), yaw)
        x0, y0 = spec.position if spec.position is not None else pts[0]
        motion = TrajectoryMotion(np.array(tr.t_s), pts[:, 0] - x0, pts[:, 1] - y0, yaws - yaw)
        pose = (x0, y0, yaw)
    else:
        motion = Static() if spec.velocity_mps is None else ConstantVelocity(*spec.velocity_mps)
        pose = (spec.position[0], spec.position[1], yaw)
    life = spec.lifetime_s if spec.lifetime_s is not None else (-math.inf, math.inf)
    return Obstacle(shape, pose, motion, spec.name, t_start_s=life[0], t_end_s=life[1])


def initial_overlap(spec: ScenarioSpec) -> tuple[str, str] | None:
    """(field, problem) for the first obstacle that overlaps the car's footprint at t = 0 (the
    body rectangle at the initial pose against the obstacle's shape at t = 0; touching is
    allowed), else None. An obstacle that cannot be built is left to :func:`build_experiment`."""
    from ..scene.geometry import shape_distance

    v, init = spec.vehicle, spec.initial_state
    body = Footprint(v.length_m, v.width_m, n_discs=v.footprint_discs).polygon(
        init.x_m, init.y_m, math.radians(init.yaw_deg)
    )
    for i, o in enumerate(spec.obstacles):
        try:
            ob = build_obstacle(o)
            if not ob.present(0.0):
                continue  # not there at the start
            d = shape_distance(body, ob.at(0.0))
        except ValueError:
            continue
        if d < 0.0:
            return (
                f"obstacles.{i}",
                f"{o.shape} obstacle{f' {o.name!r}' if o.name else ''} overlaps the car's "
                f"footprint at the start (t = 0, {-d:.3g} m deep): move it or the initial state",
            )
    return None


#: largest Froude-like speed ratio v / sqrt(g L) (L the wheelbase) a scenario runs without a
#: warning: 15 is 77 m/s for a 2.7 m passenger car (beyond its top speed, ratio about 13) and
#: 27 m/s for the 0.33 m 1:10 car (ratio 11 at 20 m/s); far beyond it no bicycle model here is
#: valid (tyre forces, aerodynamics and the discretization all break down)
MAX_FROUDE = 15.0
#: a ``_deg`` limit below this many degrees looks like radians (pi / 2: a steering limit in rad)
RADIAN_LIKE_DEG = math.pi / 2
#: a control period of at least this many seconds looks like milliseconds
MS_LIKE_DT_S = 1.0


def scenario_warnings(spec: ScenarioSpec) -> list[tuple[str, str]]:
    """(field, problem) for every legal but suspicious value: a speed far beyond what the model
    is valid for (above ``MAX_FROUDE`` sqrt(g L), L = lf + lr), a ``_deg`` limit that looks like
    radians (nonzero and below pi / 2), a ``dt_s`` or ``controller.period_s`` that looks like
    milliseconds (>= 1 s), and an initial position whose centre is outside the lane (``road``,
    else a track's road widths)."""
    out = []
    v, c = spec.vehicle, spec.controller
    wheelbase = v.lf_m + v.lr_m
    v_valid = MAX_FROUDE * math.sqrt(9.81 * wheelbase)
    speeds = [
        ("vehicle.speed_mps", v.speed_mps),
        ("plant.speed_mps", spec.plant.speed_mps),
        ("initial_state.v_mps", spec.initial_state.v_mps),
        ("controller.reference_speed_mps", c.reference_speed_mps),
        ("controller.speed_profile.v_max_mps", None if c.speed_profile is None else c.speed_profile.v_max_mps),
    ]
    for field, speed in speeds:
        if speed is not None and abs(speed) > v_valid:
            out.append(
                (
                    field,
                    f"{speed:g} m/s is far beyond what the model is valid for with a {wheelbase:.3g} m "
                    f"wheelbase (above {v_valid:.3g} m/s = {MAX_FROUDE:g} sqrt(g L)): check the value and its units",
                )
            )
    for field, deg in (
        ("controller.max_steer_deg", c.max_steer_deg),
        ("controller.max_steer_rate_deg_s", c.max_steer_rate_deg_s),
    ):
        if deg is not None and 0 < abs(deg) < RADIAN_LIKE_DEG:
            out.append(
                (
                    field,
                    f"{deg:g} looks like radians ({deg:g} rad = {math.degrees(deg):.4g} deg); this field is in degrees",
                )
            )
    if spec.dt_s >= MS_LIKE_DT_S:
        out.append(
            (
                "dt_s",
                f"a control period of {spec.dt_s:g} s looks like milliseconds "
                f"({spec.dt_s:g} ms = {spec.dt_s / 1000:g} s); dt_s is in seconds",
            )
        )
    if c.period_s is not None and c.period_s >= MS_LIKE_DT_S:
        out.append(
            (
                "controller.period_s",
                f"a control period of {c.period_s:g} s looks like milliseconds "
                f"({c.period_s:g} ms = {c.period_s / 1000:g} s); period_s is in seconds",
            )
        )
    lane = _start_outside_lane(spec)
    if lane is not None:
        out.append(("initial_state", lane))
    return out


def _start_outside_lane(spec: ScenarioSpec) -> str | None:
    """Why the initial position lies outside the lane, or None (inside, or no lane)."""
    init = spec.initial_state
    try:
        track = load_track(spec.path) if spec.path.type == "csv" else None
        if spec.road is None and (track is None or not track.has_widths):
            return None
        path = track.path if track is not None else build_path(spec.path)
    except ValueError:  # a path that cannot be built: build_experiment says why
        return None
    s, e_y = path.project(np.array([init.x_m, init.y_m], float))
    road = build_road(spec.road, path, track)
    assert road is not None  # a road spec or a track with widths (checked above)
    left_e, right_e = (float(e) for e in road.edges(s))
    left, right = left_e, -right_e
    if right_e <= e_y <= left_e:
        return None
    side, width = ("left", left) if e_y > 0 else ("right", right)
    return f"the car starts {abs(e_y):.3g} m {side} of the path, outside the lane ({width:.3g} m to its {side} edge)"


def build_goal(spec) -> PlanningGoal | None:
    """The :class:`~mpcdrive.planning.PlanningGoal` of a ``goal`` spec (None: none)."""
    if spec is None:
        return None

    def interval(v, lo=-math.inf, hi=math.inf) -> tuple[float, float]:
        if v is None:
            return lo, hi
        return (lo if v[0] is None else float(v[0])), (hi if v[1] is None else float(v[1]))

    return PlanningGoal(
        arc_m=interval(spec.arc_m),
        offset_m=interval(spec.offset_m),
        time_s=interval(spec.time_s),
        speed_mps=interval(spec.speed_mps, 0.0),
        yaw_rad=None if spec.yaw_deg is None else (math.radians(spec.yaw_deg[0]), math.radians(spec.yaw_deg[1])),
    )


def build_road(spec, path: ReferencePath, track: Track | None = None) -> Road | None:
    """The :class:`~mpcdrive.scene.road.Road` of a ``road`` spec along ``path``, else the road
    widths of a track (followed exactly, not by their narrowest), else None."""
    period = path.length_m if path.closed else 0.0
    if spec is not None:
        if spec.lane_width_m is not None:
            road = Road.constant(spec.lane_width_m, spec.margin_m)
        elif spec.widths is None:
            road = Road.per_side(spec.left_width_m, spec.right_width_m, spec.margin_m)
        else:
            s, wl, wr = (np.array(c, float) for c in zip(*spec.widths))
            road = Road.from_widths(s, wl, wr, spec.margin_m, period if s[-1] - s[0] < period else 0.0)
        if spec.start_m is not None or spec.end_m is not None:
            if period > 0:
                raise ValueError("road start_m / end_m: a closed path's road has no ends")
            road = road.with_ends(spec.start_m, spec.end_m)
        if spec.lane_rows:
            return _with_lanes(road, spec.lane_rows)
        return road if spec.neighbours is None else _with_neighbours(road, spec.neighbours)
    if track is not None and track.has_widths:
        assert track.width_left_m is not None and track.width_right_m is not None
        return Road.from_widths(track.s_points_m, track.width_left_m, track.width_right_m, 0.0, period)
    return None


def _with_lanes(road: Road, lanes) -> Road:
    """``road`` (the route lane) with the lanes of ``road.lane_rows`` beside it, on its knots."""
    s = road.s_m
    out = [Lane("route", 0.5 * (road.left_m + road.right_m), road.left_m, road.right_m)]
    for ln in lanes:
        s_n, lf, rt = (np.array(c, float) for c in zip(*ln.rows))
        left, right = np.interp(s, s_n, lf), np.interp(s, s_n, rt)
        out.append(Lane(ln.name, 0.5 * (left + right), left, right, oncoming=ln.oncoming))
    return Road(s, road.left_m, road.right_m, road.margin_m, tuple(out), 0, road.period_m, road.start_m, road.end_m)


def _with_neighbours(road: Road, rows) -> Road:
    """``road`` with three lanes on its knots: the right neighbour, ``road`` itself (the route
    lane) and the left neighbour, reaching ``rows`` ``[s_m, left_m, right_m]`` beyond its edges."""
    s_n, ext_l, ext_r = (np.array(c, float) for c in zip(*rows))
    s = road.s_m
    el, er = np.interp(s, s_n, ext_l), np.interp(s, s_n, ext_r)
    left, right = road.left_m, road.right_m
    lanes = (
        Lane("right", right - 0.5 * er, right, right - er),
        Lane("route", 0.5 * (left + right), left, right),
        Lane("left", left + 0.5 * el, left + el, left),
    )
    return Road(s, left, right, road.margin_m, lanes, 1, road.period_m, road.start_m, road.end_m)


def dynamic_params(v, scale=None) -> DynamicParams:
    """Dynamic-bicycle parameters of a vehicle spec, optionally scaled (plant.param_scale)."""
    p = DynamicParams(
        lf_m=v.lf_m,
        lr_m=v.lr_m,
        mass_kg=v.mass_kg,
        yaw_inertia_kgm2=v.yaw_inertia_kgm2,
        friction=v.friction,
        cs_front_per_rad=v.cs_front_per_rad,
        cs_rear_per_rad=v.cs_rear_per_rad,
        h_cg_m=v.h_cg_m,
        pacejka_c=v.pacejka_c,
        pacejka_e=v.pacejka_e,
        v_blend_low_mps=v.v_blend_low_mps,
        v_blend_high_mps=v.v_blend_high_mps,
    )
    if scale is not None:
        p = p.scaled(
            mass_kg=scale.mass,
            yaw_inertia_kgm2=scale.yaw_inertia,
            friction=scale.friction,
            cs_front_per_rad=scale.cornering_stiffness_front,
            cs_rear_per_rad=scale.cornering_stiffness_rear,
        )
    return p


def build_model(name: str, v, scale=None):
    """The vehicle model called ``name`` with the parameters of vehicle spec ``v``."""
    if name == "kinematic3":
        return KinematicBicycle3(v.speed_mps, KinematicParams(v.lf_m, v.lr_m))
    if name == "kinematic4":
        return KinematicBicycle4(KinematicParams(v.lf_m, v.lr_m))
    return DynamicBicycle(dynamic_params(v, scale), tire="linear" if name == "dynamic_linear" else "pacejka")


def build_speed_profile(spec, path: ReferencePath, friction: float) -> SpeedProfile:
    """The speed profile of a ``controller.speed_profile`` spec along ``path``."""
    a_lat = spec.lateral_accel_max_mps2 or spec.lateral_accel_fraction * friction * 9.81
    return SpeedProfile(
        path,
        a_lat,
        spec.accel_max_mps2,
        spec.decel_max_mps2,
        spec.v_max_mps,
        v_start_mps=spec.v_start_mps,
        v_end_mps=spec.v_end_mps,
        curvature_window_m=spec.curvature_window_m,
        friction_circle=spec.friction_circle,
        s_start_m=min(spec.start_m, float(path.length_m)),
        top_speed_until=tuple((float(su), float(vc)) for su, vc in spec.top_speed_until),
        curvature_rate_max_1pms=spec.curvature_rate_max_1pms,
    )


def build_actuator(spec) -> SteeringActuator | None:
    """The plant's steering actuator of a resolved ``plant.steering_actuator`` (None: ``ideal``, or
    a CommonRoad plant, which steers itself)."""
    if spec is None or spec == IDEAL_STEERING:
        return None
    return SteeringActuator(spec.time_constant_s, spec.dead_time_s, math.radians(spec.max_rate_deg_s))


def criteria(spec: ScenarioSpec) -> VerdictCriteria:
    """How runs of ``spec`` are judged (its ``verdict`` block)."""
    v = spec.verdict
    return VerdictCriteria(v.goal, v.max_final_lateral_error_m, v.max_final_speed_mps, v.max_lane_excess_m)


def _noise(spec: NoiseSpec | None) -> Disturbance | None:
    if spec is None:
        return None
    return Disturbance(
        spec.distribution,
        low=None if spec.low is None else np.array(spec.low),
        high=None if spec.high is None else np.array(spec.high),
        std=None if spec.std is None else np.array(spec.std),
    )


#: builds the plant of a ``plant.model`` that the core has no model of, CommonRoad's vehicle
#: models (``commonroad_ks | commonroad_st | commonroad_mb``), from that name and
#: ``plant.vehicle``: :func:`mpcdrive.adapters.commonroad_vehicles.commonroad_plant`
PlantFactory = Callable[[str, str], ObservedPlant]


def build_experiment(spec: ScenarioSpec, *, plant_factory: PlantFactory | None = None) -> Experiment:
    """Models, path, QP (built once), controller and plant of a scenario.

    A scenario on one of CommonRoad's vehicle models (``plant.model: commonroad_*``) needs
    ``plant_factory``, which builds that plant (the CommonRoad adapter's
    :func:`~mpcdrive.adapters.commonroad_vehicles.commonroad_plant`; ``mpcdrive run`` passes it):
    the scenarios know no adapter. Without one such a scenario is a ValueError."""
    if spec.plant_model in COMMONROAD_PLANTS and plant_factory is None:
        raise ValueError(
            f"plant.model {spec.plant_model} is a CommonRoad vehicle model, built by the CommonRoad adapter: "
            "build_experiment(spec, plant_factory=commonroad_plant), "
            "from mpcdrive.adapters.commonroad_vehicles import commonroad_plant"
        )
    v = spec.vehicle
    c = spec.controller
    steer = math.radians(c.max_steer_deg)
    rate = None if c.max_steer_rate_deg_s is None else math.radians(c.max_steer_rate_deg_s)
    model = build_model(v.model, v)
    track = load_track(spec.path) if spec.path.type == "csv" else None
    path = track.path if track is not None else build_path(spec.path)
    profile = None if c.speed_profile is None else build_speed_profile(c.speed_profile, path, v.friction)
    init = spec.initial_state
    pose = [init.x_m, init.y_m, math.radians(init.yaw_deg)]
    if v.model == "kinematic3":
        u_min, u_max, du = [-steer], [steer], [rate if rate else np.inf]
        x_min = x_max = None
        v_ref = v.speed_mps
    else:
        a_lo, a_hi = c.accel_limits_mps2 or (-np.inf, np.inf)
        u_min, u_max, du = [-steer, a_lo], [steer, a_hi], [rate if rate else np.inf, np.inf]
        v_ref = c.reference_speed_mps if c.reference_speed_mps is not None else v.speed_mps
        s_lo, s_hi = c.speed_limits_mps or (-np.inf, np.inf)
        nx = model.nx
        x_min, x_max = [-np.inf] * nx, [np.inf] * nx
        x_min[3], x_max[3] = s_lo, s_hi
    if profile is not None and c.reference_speed_mps is None:
        v_ref = None  # the profile gives the reference speed
    # the road: the scenario's, else the track's widths
    road = build_road(spec.road, path, track)
    problem = MpcProblem(
        nx=model.nx,
        nu=model.nu,
        N=c.horizon,
        dt_s=spec.control_period_s,  # the horizon step is the controller's period
        Q=np.array(c.Q),
        R=np.array(c.R),
        QN=None if c.QN is None else np.array(c.QN),
        Rc=None if c.Rc is None else np.array(c.Rc),
        u_min=np.array(u_min),
        u_max=np.array(u_max),
        du_max_per_s=np.array(du),
        x_min=x_min,
        x_max=x_max,
        lane_slack_weight=c.lane_slack_weight,
        lane_slack_weight_l1=c.lane_slack_weight_l1,
        friction_accel_mps2=c.friction_accel_mps2,
    )
    config = MpcConfig(
        linearization=c.linearization,
        discretization=c.discretization,
        horizon=c.horizon_reference,
        horizon_step_m=c.horizon_step_m,
        v_ref_mps=v_ref,
        feedforward=c.feedforward,
        speed_profile=profile,
        prediction_substeps=c.prediction_substeps,
        steer_weight_speed_mps=c.steer_weight_speed_mps,
        projection_window_m=c.projection_window_m,
        fallback=FallbackConfig(
            ladder=tuple(c.fallback),
            brake_decel_mps2=c.brake_decel_mps2,
            brake_steering=c.brake_steering,
            relax_slack_factor=c.relax_slack_factor,
            check_plans=c.check_plans,
        ),
    )
    pg_settings = ProjectedGradientSettings(max_iter=c.pg_max_iter, tol=c.pg_tol, accelerated=c.pg_accelerated)
    osqp_settings = OsqpSettings(
        eps_abs=c.osqp_eps,
        eps_rel=c.osqp_eps,
        max_iter=c.osqp_max_iter,
        polish=c.osqp_polish,
        adaptive_rho=c.osqp_adaptive_rho,
        time_limit_s=c.osqp_time_limit_s,
    )
    footprint = Footprint(v.length_m, v.width_m, n_discs=v.footprint_discs)
    doubled = path_doubles_back(spec, path, road)
    if doubled is not None:
        raise ValueError(": ".join(doubled))
    obstacles = tuple(build_obstacle(o) for o in spec.obstacles)
    av = spec.avoidance or AvoidanceSpec()
    avoidance = AvoidanceConfig(**{f.name: getattr(av, f.name) for f in dataclasses.fields(AvoidanceConfig)})
    if obstacles:
        config = replace(
            config, sqp_max_iterations=av.sqp_max_iterations, sqp_tol=av.sqp_tol, sqp_max_time_s=av.sqp_max_time_s
        )
    # backend fast: the default controller (compiled where it covers the problem, the condensed
    # solver; OSQP with these settings beyond its limits); osqp: the reference, assembled in Python
    reference = c.backend == "osqp" or c.solver == "projected_gradient"
    mpc = LtvMpc(
        model,
        path,
        problem,
        config,
        c.solver if reference else "condensed",
        scene=Scene(road, obstacles, footprint),  # the world, given once: the run is judged on it
        avoidance=avoidance,
        osqp_settings=osqp_settings,
        pg_settings=pg_settings,
        assembly="python" if reference else "auto",
    )
    # the plant: same or another model, parameters scaled, steering through an actuator
    pl = spec.plant
    # the true vehicle: the controller's unless the plant names other parameters (a model error)
    errors = {
        k: val for k, val in (("lf_m", pl.lf_m), ("lr_m", pl.lr_m), ("speed_mps", pl.speed_mps)) if val is not None
    }
    plant_v = v.model_copy(update=errors) if errors else v
    same = pl.model == "same" and pl.param_scale is None and not errors
    if spec.plant_model in COMMONROAD_PLANTS:
        assert plant_factory is not None  # checked above
        plant = plant_factory(spec.plant_model, pl.vehicle)
        plant_model = plant.model  # observed as kinematic4 (x, y, yaw, v at the centre of gravity)
    else:
        plant_model = model if same else build_model(spec.plant_model, plant_v, pl.param_scale)
    actuator = build_actuator(pl.steering_actuator)
    controller: Controller = mpc
    if road is not None and (road.lanes or spec.planner is not None):
        # a road with lanes (or a scenario asking for it): the maneuver planner chooses the lane,
        # the offset and the speed
        settings = dict(spec.planner or {})
        replan_s = float(settings.pop("replan_s", 0.0))
        cfg = PlannerConfig(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in settings.items()})
        controller = PlannedMpc(mpc, road, cfg, goal=build_goal(spec.goal), replan_s=replan_s)
    if c.delay_compensation:
        # predicts over its own period with the plant's integration step
        period_steps = int(round(spec.control_period_s / spec.dt_s))
        controller = DelayCompensator(
            mpc, model, actuator, spec.control_period_s, path, substeps=pl.substeps * period_steps
        )
    if tuple(plant_model.state_names) != tuple(model.state_names):
        controller = StateAdapter(controller, model, plant_model)
    if spec.plant_model not in COMMONROAD_PLANTS:
        plant = Plant(plant_model, pl.integrator, pl.substeps, actuator)
    # initial plant state: the pose, the given speed (else the reference / profile speed)
    if init.v_mps is not None:
        v0 = init.v_mps
    elif profile is not None:
        v0 = float(profile.speed(path.project(np.array(pose[:2]))[0]))
    else:
        v0 = v_ref
    names = plant_model.state_names
    x0 = np.zeros(plant_model.nx)
    x0[:3] = pose
    if "v" in names:
        x0[names.index("v")] = v0
    if "vx" in names:
        x0[names.index("vx")] = v0
    return Experiment(
        spec=spec,
        path=path,
        controller=controller,
        plant=plant,
        x0=x0,
        steps=max(1, int(round(spec.duration_s / spec.dt_s))),
        footprint=footprint,
        disturbance=_noise(spec.disturbance),
        measurement_noise=_noise(spec.measurement_noise),
        obstacles=obstacles,
        mpc=mpc,
        track=track,
        speed_profile=profile,
        road=road,
    )


def run_experiment(exp: Experiment, progress: Callable[[int, int], None] | None = None) -> SimResult:
    """Closed-loop run of a built experiment."""
    spec = exp.spec
    pb = (exp.mpc or exp.controller).problem
    # the run is judged against the controller's scene: the whole road (a pass through a
    # neighbour lane is inside), the obstacles, the body
    road = None if exp.road is None else exp.road.whole()
    res = simulate(
        exp.controller,
        exp.plant,
        exp.path,
        exp.x0,
        spec.dt_s,
        exp.steps,
        disturbance=exp.disturbance,
        measurement_noise=exp.measurement_noise,
        seed=spec.seed,
        stop_at_path_end=spec.stop_at_path_end,
        progress=progress,
        meta={
            "id": spec.id,
            "max_steer_rad": float(pb.u_max[0]),
            "description": spec.description,
            "backend": getattr(exp.mpc, "backend_name", ""),
            "criteria": criteria(spec).as_dict(),
        },
        laps=spec.laps,
        # on a track, a car more than 1 m beyond the road edge has left it for good
        abort_lateral_error_m=None if exp.track is None or road is None else road.max_offset_m + 1.0,
        control_period_s=spec.controller.period_s,
        between_solves=spec.controller.between_solves,
    )
    planner_stats = inner_attr(exp.controller, "planner_stats")  # a maneuver planner's, where one drives
    if planner_stats is not None:
        res.meta["planner"] = planner_stats()
    return res
