"""Turn a validated scenario into core objects and run it."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..control.base import Controller
from ..control.factory import make_mpc
from ..control.mpc import MpcConfig
from ..models.kinematic import KinematicBicycle3, KinematicBicycle4, KinematicParams
from ..ocp.problem import MpcProblem
from ..paths import CirclePath, Path, StraightPath, WaypointPath
from ..sim.closed_loop import Disturbance, Plant, simulate
from ..sim.metrics import Footprint
from ..solvers.osqp_backend import OsqpSettings
from ..types import SimResult
from .schema import NoiseSpec, ScenarioSpec


@dataclass(frozen=True)
class Experiment:
    """Everything a run needs, built from a scenario."""

    spec: ScenarioSpec
    path: Path
    controller: Controller
    plant: Plant
    x0: np.ndarray
    steps: int
    footprint: Footprint
    disturbance: Disturbance | None
    measurement_noise: Disturbance | None


def build_path(spec) -> Path:
    if spec.type == "straight":
        return StraightPath(spec.start, spec.end)
    if spec.type == "circle":
        return CirclePath(spec.center, spec.radius_m, spec.ccw, math.radians(spec.start_angle_deg))
    return WaypointPath(spec.points, closed=spec.closed, smoothing=spec.smoothing)


def _noise(spec: NoiseSpec | None) -> Disturbance | None:
    if spec is None:
        return None
    return Disturbance(
        spec.distribution,
        low=None if spec.low is None else np.array(spec.low),
        high=None if spec.high is None else np.array(spec.high),
        std=None if spec.std is None else np.array(spec.std),
    )


def build_experiment(spec: ScenarioSpec) -> Experiment:
    """Models, path, QP (built once), controller and plant of a scenario."""
    v = spec.vehicle
    params = KinematicParams(v.lf_m, v.lr_m)
    c = spec.controller
    steer = math.radians(c.max_steer_deg)
    rate = None if c.max_steer_rate_deg_s is None else math.radians(c.max_steer_rate_deg_s)
    if v.model == "kinematic3":
        model = KinematicBicycle3(v.speed_mps, params)
        u_min, u_max, du = [-steer], [steer], [rate if rate else np.inf]
        x_min = x_max = None
        x0 = np.array([spec.initial_state.x_m, spec.initial_state.y_m, math.radians(spec.initial_state.yaw_deg)])
        v_ref = v.speed_mps
    else:
        model = KinematicBicycle4(params)
        a_lo, a_hi = c.accel_limits_mps2 or (-np.inf, np.inf)
        u_min, u_max, du = [-steer, a_lo], [steer, a_hi], [rate if rate else np.inf, np.inf]
        v_ref = c.reference_speed_mps if c.reference_speed_mps is not None else v.speed_mps
        s_lo, s_hi = c.speed_limits_mps or (-np.inf, np.inf)
        x_min, x_max = [-np.inf] * 3 + [s_lo], [np.inf] * 3 + [s_hi]
        v0 = spec.initial_state.v_mps if spec.initial_state.v_mps is not None else v_ref
        x0 = np.array([spec.initial_state.x_m, spec.initial_state.y_m, math.radians(spec.initial_state.yaw_deg), v0])
    lane_half = None if spec.road is None else spec.road.lane_width_m / 2.0
    problem = MpcProblem(
        nx=model.nx,
        nu=model.nu,
        N=c.horizon,
        dt_s=spec.dt_s,
        Q=np.array(c.Q),
        R=np.array(c.R),
        QN=None if c.QN is None else np.array(c.QN),
        Rc=None if c.Rc is None else np.array(c.Rc),
        u_min=np.array(u_min),
        u_max=np.array(u_max),
        du_max_per_s=np.array(du),
        x_min=x_min,
        x_max=x_max,
        lane_half_width_m=lane_half,
        lane_slack_weight=c.lane_slack_weight,
        lane_slack_weight_l1=c.lane_slack_weight_l1,
    )
    config = MpcConfig(
        linearization=c.linearization,
        discretization=c.discretization,
        horizon=c.horizon_reference,
        horizon_step_m=c.horizon_step_m,
        v_ref_mps=v_ref,
        feedforward=c.feedforward,
    )
    path = build_path(spec.path)
    controller = make_mpc(model, path, problem, config, c.backend,
                          OsqpSettings(eps_abs=c.osqp_eps, eps_rel=c.osqp_eps, max_iter=c.osqp_max_iter))
    plant = Plant(model, spec.plant.integrator, spec.plant.substeps)
    return Experiment(
        spec=spec,
        path=path,
        controller=controller,
        plant=plant,
        x0=x0,
        steps=max(1, int(round(spec.duration_s / spec.dt_s))),
        footprint=Footprint(v.length_m, v.width_m),
        disturbance=_noise(spec.disturbance),
        measurement_noise=_noise(spec.measurement_noise),
    )


def run_experiment(exp: Experiment, progress: Callable[[int, int], None] | None = None) -> SimResult:
    """Closed-loop run of a built experiment."""
    spec = exp.spec
    pb = exp.controller.problem
    return simulate(
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
        lane_half_width_m=pb.lane_half_width_m,
        progress=progress,
        meta={"id": spec.id, "max_steer_rad": float(pb.u_max[0]), "description": spec.description,
              "backend": getattr(exp.controller, "backend_name", "")},
    )
