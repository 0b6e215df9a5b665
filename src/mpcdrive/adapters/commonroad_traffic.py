"""Which traffic a CommonRoad drive meets and what the controller knows of it.

* ``traffic``: ``recorded`` (the scenario's vehicles replay their recordings) or ``sumo`` (SUMO
  drives them from their recorded starts and routes, reacting to the ego:
  :mod:`.commonroad_sumo`).
* ``prediction``: ``known`` (the controller is handed each vehicle's recorded future, CommonRoad's
  benchmark convention; recorded traffic only: SUMO's future does not exist yet) or ``lane``
  (each vehicle observed now and predicted at constant speed along its lane with a growing
  uncertainty: :mod:`mpcdrive.prediction`), for either traffic.

:func:`with_traffic` sets both on an import; the import's ``prepare_experiment`` then applies
them to the built experiment (:func:`prepare`), and its ``write_outputs`` judges a SUMO drive
against the vehicles as SUMO drove them (:func:`driven_scenario`) and writes ``sumo.json``
(:func:`sumo_report`: the co-simulation's facts, SUMO's time per step and the SUMO-driver
baseline on the ego's route).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

TRAFFIC_MODES = ("recorded", "sumo")
PREDICTIONS = ("known", "lane")
#: obstacles the controller considers per step, with lane predictions (each car is one obstacle
#: per time band, two of them within a 3 s horizon): the known-future import's 4 cars
MAX_OBSTACLES_LANE = 8


def check_modes(traffic: str | None, prediction: str | None) -> tuple[str, str]:
    """``(traffic, prediction)`` with the defaults filled in (``recorded`` and ``known``; ``lane``
    for SUMO traffic); ValueError naming the option for an unknown name or ``sumo`` with
    ``known``."""
    traffic = traffic or "recorded"
    if traffic not in TRAFFIC_MODES:
        raise ValueError(f"--traffic: unknown traffic {traffic!r} (known: {', '.join(TRAFFIC_MODES)})")
    prediction = prediction or ("lane" if traffic == "sumo" else "known")
    if prediction not in PREDICTIONS:
        raise ValueError(f"--prediction: unknown prediction {prediction!r} (known: {', '.join(PREDICTIONS)})")
    if traffic == "sumo" and prediction == "known":
        raise ValueError("--prediction known: SUMO traffic has no known future (use --prediction lane)")
    return traffic, prediction


def lane_map(scenario):
    """The scenario's lanelets as a :class:`~mpcdrive.prediction.LaneMap` (centre lines,
    successors, half widths)."""
    from ..prediction import Lane, LaneMap

    lanes = []
    for ll in scenario.lanelet_network.lanelets:
        c = np.asarray(ll.center_vertices, float)
        w = np.hypot(*(np.asarray(ll.left_vertices, float) - np.asarray(ll.right_vertices, float)).T)
        try:
            lanes.append(Lane(int(ll.lanelet_id), c, tuple(ll.successor or ()), max(0.5 * float(np.median(w)), 0.5)))
        except ValueError:
            continue  # a degenerate lanelet (zero length) is no lane to follow
    return LaneMap(lanes)


def lane_trajectories(scenario, dt_s: float, duration_s: float) -> dict[int, dict]:
    """The trajectory entries (``t_s``, ``points``, ``yaw_deg``), by obstacle id, of the moving
    vehicles of ``scenario`` known by their initial state only (an interactive scenario's
    traffic, which a traffic simulator would drive): each one's initial speed held along its lane
    (:func:`lane_map`; straight on where it is on none) every ``dt_s`` [s] over ``duration_s``
    [s], as :class:`~mpcdrive.prediction.LanePredictor` predicts a car. A car standing (below the
    predictor's least speed) has none: it stays where it is."""
    from ..prediction import LanePredictor
    from ..prediction.predictor import Observation, PredictionConfig

    horizon = max(float(duration_s), dt_s)
    cfg = PredictionConfig(horizon_s=horizon, dt_s=dt_s, bands_s=(horizon,))
    moving = [
        o
        for o in scenario.dynamic_obstacles
        if o.prediction is None and float(getattr(o.initial_state, "velocity", 0.0) or 0.0) >= cfg.min_speed_mps
    ]
    if not moving:
        return {}
    pred = LanePredictor(lane_map(scenario), cfg)
    out = {}
    for o in moving:
        st = o.initial_state
        x, y = (float(c) for c in np.asarray(st.position, float)[:2])
        yaw = float(getattr(st, "orientation", 0.0) or 0.0)
        P, yaws = pred.path(Observation(0.0, (x, y, yaw), float(st.velocity), None))  # type: ignore[arg-type]
        t0 = float(st.time_step) * dt_s
        out[o.obstacle_id] = {
            "t_s": [t0 + float(t) for t in pred.taus_s],
            "points": [(float(a), float(b)) for a, b in P],
            "yaw_deg": [math.degrees(float(h)) for h in yaws],
        }
    return out


def with_traffic(imp, traffic: str | None = None, prediction: str | None = None, settings=None):
    """``imp`` driven among ``traffic`` with ``prediction`` (:func:`check_modes`; ValueError as
    there, and naming the extra when SUMO is not installed). SUMO traffic lasts at least
    ``settings.duration_s`` (:class:`~.commonroad_sumo.SumoSettings`); lane predictions widen the
    controller's obstacle budget to :data:`MAX_OBSTACLES_LANE`."""
    traffic, prediction = check_modes(traffic, prediction)
    spec = imp.spec
    if traffic == "sumo":
        from .commonroad_sumo import INSTALL_HINT, SumoSettings, available

        if not available():
            raise ValueError(f"--traffic sumo needs the sumo extra ({INSTALL_HINT})")
        settings = settings or SumoSettings()
        spec = spec.model_copy(update={"duration_s": max(spec.duration_s, settings.duration_s)})
    if prediction == "lane" and spec.avoidance is not None:
        av = spec.avoidance.model_copy(update={"max_obstacles": max(spec.avoidance.max_obstacles, MAX_OBSTACLES_LANE)})
        spec = spec.model_copy(update={"avoidance": av})
    return dataclasses.replace(imp, spec=spec, traffic=traffic, prediction=prediction, sumo=settings, runtime={})


def _recorded_ids(obstacles, ids) -> tuple:
    """The obstacles whose import name ends in one of the CommonRoad ``ids``."""
    want = {str(i) for i in ids}
    return tuple(o for o in obstacles if o.name.rsplit("-", 1)[-1] in want)


def prepare(imp, exp):
    """The built experiment ``exp`` of ``imp`` with its traffic and prediction: SUMO as the
    plant's traffic (the vehicles it drives leave the scenario's obstacles; static ones and
    those it cannot route stay), and with ``lane`` the controller wrapped to see predictions."""
    if imp.traffic == "recorded" and imp.prediction == "known":
        return exp
    obstacles = exp.obstacles
    plant = exp.plant
    if imp.traffic == "sumo":
        from .commonroad_sumo import SumoTrafficPlant, build_sumo_files, tempdir

        tmp = tempdir()
        imp.runtime["tempdir"] = tmp
        files = build_sumo_files(imp.scenario, tmp.name, imp.sumo)
        driven = {str(v.id) for v in files.vehicles}
        obstacles = tuple(o for o in exp.obstacles if o.name.rsplit("-", 1)[-1] not in driven)
        v = imp.spec.vehicle
        plant = SumoTrafficPlant(
            exp.plant,
            files,
            dt_s=imp.spec.dt_s,
            ego_shape=(v.length_m, v.width_m),
            centerline=imp.centerline,
            settings=imp.sumo,
        )
        imp.runtime["plant"] = plant
        if exp.mpc is not None and getattr(exp.mpc, "avoidance", None) is not None:
            exp.mpc.set_obstacles(obstacles)  # no recorded future of a SUMO vehicle reaches the controller
        # the world the drive is judged in: the obstacles SUMO does not drive, and its traffic
        # (the plant's, added by the closed loop) in place of the recordings
        c = exp.controller
        for _ in range(8):  # the controller and those it wraps
            if c is None:
                break
            if "scene" in vars(c):
                c.scene = dataclasses.replace(c.scene, obstacles=obstacles)
            c = vars(c).get("inner") or vars(c).get("mpc")
    controller = exp.controller
    if imp.prediction == "lane" and getattr(exp.mpc, "avoidance", None) is not None:  # else nothing to predict
        from ..prediction import LanePredictor, PredictingController

        controller = PredictingController(
            exp.controller,
            LanePredictor(lane_map(imp.scenario)),
            obstacles,
            period_s=imp.spec.control_period_s,
            target=exp.mpc,
        )
    return dataclasses.replace(exp, plant=plant, controller=controller, obstacles=obstacles)


def driven_scenario(imp, plant):
    """A copy of ``imp``'s scenario in which the vehicles SUMO drove are dynamic obstacles
    following the states SUMO gave them (from their first to their last step in SUMO; a
    vehicle SUMO never inserted is absent); every other obstacle as it was."""
    import copy

    from commonroad.geometry.shape import Rectangle
    from commonroad.prediction.prediction import TrajectoryPrediction
    from commonroad.scenario.obstacle import DynamicObstacle
    from commonroad.scenario.state import InitialState, KSState
    from commonroad.scenario.trajectory import Trajectory

    sc = copy.deepcopy(imp.scenario)
    by_id = {v.id: v for v in plant.files.vehicles}
    for vid in by_id:
        o = sc.obstacle_by_id(vid)
        if o is not None:
            sc.remove_obstacle(o)
    for vid, states in sorted(plant.log.states.items()):
        veh = by_id[vid]
        orig = imp.scenario.obstacle_by_id(vid)
        ks = sorted(states)
        st = [
            dict(position=np.array([states[k].x_m, states[k].y_m]), orientation=states[k].yaw_rad,
                 velocity=states[k].v_mps, time_step=k)
            for k in ks
        ]  # fmt: skip
        init = InitialState(**st[0], acceleration=0.0, yaw_rate=0.0, slip_angle=0.0)
        shape = Rectangle(veh.length_m, veh.width_m)
        pred = None
        if len(st) > 1:
            traj = Trajectory(ks[1], [KSState(steering_angle=0.0, **s) for s in st[1:]])
            pred = TrajectoryPrediction(traj, shape)
        sc.add_objects(DynamicObstacle(vid, orig.obstacle_type, shape, init, pred))
    return sc


def _comfort(t_s: np.ndarray, v_mps: np.ndarray) -> dict:
    """RMS and extreme longitudinal acceleration [m/s^2] and RMS jerk [m/s^3] of a speed log."""
    if len(t_s) < 3:
        return {"rms_accel_mps2": None, "min_accel_mps2": None, "rms_jerk_mps3": None}
    a = np.diff(v_mps) / np.diff(t_s)
    j = np.diff(a) / np.diff(t_s)[1:]
    return {
        "rms_accel_mps2": float(np.sqrt(np.mean(a**2))),
        "min_accel_mps2": float(a.min()),
        "rms_jerk_mps3": float(np.sqrt(np.mean(j**2))),
    }


def _progress_m(path_xy: np.ndarray, xy: np.ndarray) -> float:
    """Arc length [m] along the polyline ``path_xy`` of the point nearest to ``xy``."""
    seg = np.diff(path_xy, axis=0)
    L = np.hypot(seg[:, 0], seg[:, 1])
    ok = L > 1e-12
    seg, L, a = seg[ok], L[ok], path_xy[:-1][ok]
    t = np.clip(np.einsum("ij,ij->i", xy - a, seg) / L**2, 0.0, 1.0)
    foot = a + t[:, None] * seg
    i = int(np.argmin(np.hypot(*(xy - foot).T)))
    return float(np.r_[0.0, np.cumsum(L)][i] + t[i] * L[i])


def sumo_baseline(imp, plant, steps: int) -> dict:
    """The ego replaced by a SUMO driver on its route among the same traffic (a new SUMO run
    from the same start, same seed) for ``steps`` steps: its progress along the reference path
    [m], its comfort, whether it reached the goal (CommonRoad's goal test on its states)."""
    from commonroad.scenario.state import CustomState

    from .commonroad_sumo import SumoSession

    x0 = imp.spec.initial_state
    pose = (x0.x_m, x0.y_m, math.radians(x0.yaw_deg))
    v0 = float(x0.v_mps or 0.0)
    v = imp.spec.vehicle
    session = SumoSession(plant.files, imp.spec.dt_s, plant.settings)
    t, xs, speeds = [], [], []
    try:
        session.start(pose, v0, (v.length_m, v.width_m), plant.session.ego_route, driver=True)
        for k in range(steps):
            s = session.ego_state()
            if s is None:
                break
            t.append(k * imp.spec.dt_s)
            xs.append((s.x_m, s.y_m, s.yaw_rad))
            speeds.append(s.v_mps)
            session.step()
    finally:
        session.close()
    if not xs:
        return {"steps": 0, "progress_m": None, "goal_reached": None}
    X = np.asarray(xs)
    goal = None
    for k in range(1, len(X)):
        st = CustomState(position=X[k, :2], orientation=float(X[k, 2]), velocity=float(speeds[k]), time_step=k)
        if imp.planning_problem.goal.is_reached(st):
            goal = k
            break
    return {
        "steps": len(X),
        "progress_m": _progress_m(np.asarray(imp.centerline, float), X[-1, :2]),
        "goal_reached": goal is not None,
        "goal_step": goal,
        **_comfort(np.asarray(t), np.asarray(speeds)),
    }


def position_jumps(plant, slack_m: float = 1.0) -> list[dict]:
    """The steps at which a SUMO vehicle moved farther than its speed allows (more than
    ``max(v_before, v_after) dt + slack_m``): where the converted net's junction lanes do not
    join the lanes they lead to, SUMO moves a car across the gap in one step. ``vehicle`` (its
    CommonRoad id), ``step`` and ``jump_m``."""
    out = []
    dt = plant.dt_s
    for vid, states in sorted(plant.log.states.items()):
        ks = sorted(states)
        for a, b in zip(ks, ks[1:]):
            if b != a + 1:
                continue
            sa, sb = states[a], states[b]
            d = math.hypot(sb.x_m - sa.x_m, sb.y_m - sa.y_m)
            if d > max(sa.v_mps, sb.v_mps) * dt + slack_m:
                out.append({"vehicle": vid, "step": b, "jump_m": round(d, 2)})
    return out


def sumo_report(imp, plant, result, whole=None) -> dict:
    """``sumo.json``: the co-simulation's facts (vehicles SUMO drove, those kept as recorded,
    the ego's SUMO route, :func:`position_jumps`), SUMO's time per step [ms] (wall time), the drivability checker's
    verdicts over the whole drive against the vehicles as SUMO drove them (``whole``, a
    :class:`~.commonroad.CheckReport`), and the ego's progress and comfort beside the
    SUMO-driver baseline's (:func:`sumo_baseline`)."""
    steps = len(result.t_s)
    ego = {
        "steps": steps,
        "progress_m": _progress_m(np.asarray(imp.centerline, float), np.asarray(result.x[-1, :2], float)),
        **_comfort(np.asarray(result.t_s, float), np.asarray(result.v_mps, float)),
    }
    return {
        "vehicles_simulated": len(plant.files.vehicles),
        "vehicles_in_sumo": len(plant.log.states),
        "vehicles_recorded": list(plant.files.unrouted),
        "map_matching_m": plant.settings.map_matching_m,
        "seed": plant.settings.seed,
        "ego_route_edges": list(plant.session.ego_route),
        "ego_off_route_steps": plant.session.off_route_steps,
        "sumo_step_ms": plant.sumo_step_ms(),
        "cosim_step_ms": plant.cosim_step_ms(),
        "position_jumps": position_jumps(plant),
        "whole_drive": None
        if whole is None
        else {
            "collision_free": whole.collision_free,
            "road_compliant": whole.road_compliant,
            "states": whole.steps_checked,
        },
        "ego": ego,
        "sumo_driver": sumo_baseline(imp, plant, steps),
    }
