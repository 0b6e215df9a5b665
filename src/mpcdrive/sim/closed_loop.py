"""Closed loop: a controller drives a plant model (possibly different from its own model)."""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from ..control.base import Controller
from ..models.base import VehicleModel
from ..models.discretize import Method, discrete_step
from ..paths.base import Path
from ..scene.footprint import Footprint
from ..scene.geometry import shape_distance
from ..scene.obstacles import Circle, Obstacle
from ..types import SimResult
from .actuator import ActuatorState, SteeringActuator


@dataclass(frozen=True)
class Plant:
    """The simulated vehicle: ``model`` integrated with ``method`` in ``substeps`` per control step.

    actuator : optional steering actuator (dead time, first-order lag) between the command and
    the wheels (input 0); None applies commands instantly."""

    model: VehicleModel
    method: Method = "rk4"
    substeps: int = 1
    actuator: SteeringActuator | None = None

    def __post_init__(self):
        if not isinstance(self.model, VehicleModel):
            raise ValueError(f"plant model must be a vehicle model (f, jacobians, speed, ...), got {type(self.model).__name__}")
        if self.method not in ("rk4", "euler"):
            raise ValueError(f"plant method must be 'rk4' or 'euler', got {self.method!r}")
        if isinstance(self.substeps, bool) or not isinstance(self.substeps, numbers.Integral) or self.substeps < 1:
            raise ValueError(f"plant substeps must be an integer >= 1, got {self.substeps!r}")

    def step(self, x: np.ndarray, u: np.ndarray, dt_s: float) -> np.ndarray:
        h = dt_s / self.substeps
        for _ in range(self.substeps):
            x = discrete_step(self.model, x, u, h, self.method)
        return x

    def step_actuated(self, x: np.ndarray, u: np.ndarray, dt_s: float, act: ActuatorState,
                      t_s: float) -> tuple[np.ndarray, ActuatorState]:
        """One control step from time ``t_s`` with the steering passed through the actuator, whose
        state ``act`` already holds the command ``u[0]``; returns (state, actuator state)."""
        h = dt_s / self.substeps
        ui = np.array(u, dtype=float)
        for i in range(self.substeps):
            ui[0], act = self.actuator.advance(act, t_s + i * h, h)
            x = discrete_step(self.model, x, ui, h, self.method)
        return x, act


@runtime_checkable
class ObservedPlant(Protocol):
    """A simulated vehicle with a state layout of its own, seen by the closed loop through a
    mapping onto the layout of ``model`` (the controller's model): the loop logs, measures and
    judges the observed state, and the plant integrates its own.

    model : the vehicle model whose state layout (names, speed) the plant is observed in.
    initial_state(x0) : the plant state for the observed initial state ``x0``.
    step(xp, u, dt_s) : the plant state after holding the command ``u`` for ``dt_s`` seconds.
    observe(xp) : the observed state ``(model.nx,)`` of the plant state ``xp``.
    """

    model: VehicleModel

    def initial_state(self, x0: np.ndarray) -> np.ndarray: ...

    def step(self, xp: np.ndarray, u: np.ndarray, dt_s: float) -> np.ndarray: ...

    def observe(self, xp: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class Disturbance:
    """Random additive noise (seeded).

    distribution : ``uniform`` (each component in [low, high]) or ``normal`` (mean 0, std);
    low/high/std : (nx,) per state component, in state units.
    Used both for state disturbances (added to the plant state after each step) and for
    measurement noise (added to the state the controller sees).
    """

    distribution: str = "normal"
    low: np.ndarray | None = None
    high: np.ndarray | None = None
    std: np.ndarray | None = None

    def __post_init__(self):
        if self.distribution == "uniform":
            if self.low is None or self.high is None:
                raise ValueError("a uniform disturbance needs low and high")
            for name in ("low", "high"):
                _finite_array(getattr(self, name), f"disturbance {name}")
            if np.any(np.asarray(self.low, float) > np.asarray(self.high, float)):
                raise ValueError("disturbance low exceeds high")
        elif self.distribution == "normal":
            if self.std is None:
                raise ValueError("a normal disturbance needs std >= 0")
            std = _finite_array(self.std, "disturbance std")
            if np.any(std < 0):
                raise ValueError(f"disturbance std must be >= 0, got {self.std}")
        else:
            raise ValueError(f"distribution must be 'uniform' or 'normal', got {self.distribution!r}")

    def check(self, nx: int, name: str = "disturbance") -> None:
        """ValueError unless every parameter is a scalar or has one entry per state (``nx``)."""
        for field in ("low", "high", "std"):
            v = getattr(self, field)
            if v is not None and np.ndim(v) and np.shape(v) != (nx,):
                raise ValueError(f"{name}.{field} needs {nx} entries (one per state), got shape {np.shape(v)}")

    def sample(self, rng: np.random.Generator, nx: int) -> np.ndarray:
        if self.distribution == "uniform":
            lo = np.broadcast_to(np.asarray(self.low, float), (nx,))
            hi = np.broadcast_to(np.asarray(self.high, float), (nx,))
            return rng.uniform(lo, hi)
        return rng.normal(0.0, np.broadcast_to(np.asarray(self.std, float), (nx,)))


def _finite_array(v, name: str) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numbers, got {v!r}") from None
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, got {v!r}")
    return a


def _check_run_args(dt_s, steps, seed, lane_half_width_m) -> None:
    if isinstance(dt_s, bool) or not isinstance(dt_s, numbers.Real) or not (math.isfinite(dt_s) and dt_s > 0):
        raise ValueError(f"dt_s must be a positive finite number, got {dt_s!r}")
    if isinstance(steps, bool) or not isinstance(steps, numbers.Integral) or steps < 1:
        raise ValueError(f"steps must be an integer >= 1, got {steps!r}")
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
    if lane_half_width_m is not None and not (
        isinstance(lane_half_width_m, numbers.Real) and math.isfinite(lane_half_width_m) and lane_half_width_m > 0
    ):
        raise ValueError(f"lane_half_width_m must be a positive finite number or None, got {lane_half_width_m!r}")


def simulate(
    controller: Controller,
    plant: Plant | ObservedPlant,
    path: Path,
    x0,
    dt_s: float,
    steps: int,
    *,
    disturbance: Disturbance | None = None,
    measurement_noise: Disturbance | None = None,
    seed: int = 0,
    stop_at_path_end: bool = True,
    lane_half_width_m: float | None = None,
    progress: Callable[[int, int], None] | None = None,
    meta: dict | None = None,
    obstacles: tuple[Obstacle, ...] = (),
    footprint: Footprint = Footprint(),
    laps: float | None = None,
    abort_lateral_error_m: float | None = None,
) -> SimResult:
    """Run ``steps`` control steps of ``dt_s`` seconds from ``x0`` (plant state).

    The controller sees the plant state plus ``measurement_noise``; the plant state receives
    ``disturbance`` after every step. On an open path the run ends when the vehicle passes the
    path's end (``stop_at_path_end``), and ``goal_reached`` says whether it did.
    ``progress(k, steps)`` is called every step when given. With ``obstacles`` the clearance
    between the vehicle ``footprint`` and every obstacle is measured at each step
    (``SimResult.clearance_m``; negative = overlap) and the obstacles' poses are logged in
    ``meta["obstacles"]``.
    On a closed path, ``laps`` ends the
    run once the vehicle has driven that many laps from its start (``goal_reached`` says whether
    it did within ``steps``). ``abort_lateral_error_m`` ends the run early when the lateral error
    exceeds it (the car left the road; ``goal_reached`` is then False and
    ``meta["aborted_off_path"]`` True).

    An :class:`ObservedPlant` starts from ``initial_state(x0)`` and is seen (by the controller,
    the log and the metrics) as ``observe(plant state)``; its own state is not logged (the last
    one is ``meta["plant_state_final"]``); state ``disturbance`` needs a :class:`Plant`.

    Invalid arguments raise ValueError naming the argument. A plant state that stops being finite
    ends the run early (``meta["termination"] = "diverged"``, the last finite state as
    ``x_final``); otherwise ``termination`` is ``goal_reached`` or ``completed``.
    """
    _check_run_args(dt_s, steps, seed, lane_half_width_m)
    observed = not isinstance(plant, Plant)
    if observed and not isinstance(plant, ObservedPlant):
        raise ValueError(f"plant must be a Plant or an ObservedPlant, got {type(plant).__name__}")
    if observed and disturbance is not None:
        raise ValueError("a state disturbance needs a Plant (an ObservedPlant's state has its own layout)")
    if not isinstance(path, Path):
        raise ValueError(f"path must be a Path, got {type(path).__name__}")
    rng = np.random.default_rng(seed)
    nx, nu, N = controller.nx, controller.nu, controller.N
    model = plant.model
    try:
        x = np.array(x0, dtype=float).reshape(-1) if np.ndim(x0) <= 1 else np.asarray(x0, float)
    except (TypeError, ValueError):
        raise ValueError(f"initial state x0 must be {model.nx} numbers {model.state_names}, got {x0!r}") from None
    if x.shape != (model.nx,):
        raise ValueError(f"initial state x0 must have shape ({model.nx},) {model.state_names}, got {x.shape}")
    bad = [n for n, v in zip(model.state_names, x) if not math.isfinite(v)]
    if bad:
        raise ValueError(f"initial state x0 field(s) {', '.join(bad)} not finite: {dict(zip(model.state_names, x.tolist()))}")
    if model.nx != nx:
        raise ValueError("plant and controller must share the state layout (same nx)")
    for name, noise in (("disturbance", disturbance), ("measurement_noise", measurement_noise)):
        if noise is not None:
            if not isinstance(noise, Disturbance):
                raise ValueError(f"{name} must be a Disturbance or None, got {type(noise).__name__}")
            noise.check(nx, name)
    T = np.empty(steps)
    Xs = np.empty((steps, nx))
    Us = np.empty((steps, nu))
    S = np.empty(steps)
    EY = np.empty(steps)
    EPSI = np.empty(steps)
    XP = np.empty((steps, N + 1, nx))
    RF = np.empty((steps, N + 1, nx))
    ST = np.empty(steps)
    status: list[str] = []
    fallback: list[str] = []
    xp = plant.initial_state(x) if observed else None
    if observed:
        x = np.asarray(plant.observe(xp), float)
    warm = controller.initial_warm(x)
    goal_reached = False if (stop_at_path_end and not path.closed) else None
    s_goal = None
    if laps is not None and path.closed:
        if not laps > 0:
            raise ValueError(f"laps must be positive, got {laps}")
        s_goal = warm.s_m + laps * path.length_m
        goal_reached = False
    k_end = steps
    act = None if observed or plant.actuator is None else plant.actuator.start(0.0)  # wheels start straight
    aborted = False
    termination = "completed"
    for k in range(steps):
        meas = x if measurement_noise is None else x + measurement_noise.sample(rng, nx)
        out = controller.step(meas, warm)
        warm = out.warm
        # Frenet coordinates of the true state (the controller's are of the measurement)
        if measurement_noise is None:
            s, ey, epsi = out.s_m, out.e_y_m, out.e_psi_rad
        else:
            fr = path.frenet(x[:3], out.s_m)
            s, ey, epsi = fr.s_m, fr.e_y_m, fr.e_psi_rad
        T[k], Xs[k], Us[k] = k * dt_s, x, out.u
        S[k], EY[k], EPSI[k] = s, ey, epsi
        XP[k], RF[k], ST[k] = out.X_pred, out.refs, out.solve_time_s
        status.append(out.status)
        fallback.append(out.fallback)
        if observed:
            xp_next = np.asarray(plant.step(xp, out.u, dt_s), float)
            x_next = np.asarray(plant.observe(xp_next), float) if np.all(np.isfinite(xp_next)) else xp_next
        elif act is None:
            x_next = plant.step(x, out.u, dt_s)
        else:
            act = act.issue(k * dt_s, float(out.u[0]))
            x_next, act = plant.step_actuated(x, out.u, dt_s, act, k * dt_s)
        if disturbance is not None:
            x_next = x_next + disturbance.sample(rng, nx)
        if progress is not None:
            progress(k + 1, steps)
        if not np.all(np.isfinite(x_next)):
            termination = "diverged"
            k_end = k + 1
            break
        x = x_next
        if observed:
            xp = xp_next
        if goal_reached is not None and s >= (path.length_m if s_goal is None else s_goal):
            goal_reached = True
            termination = "goal_reached"
            k_end = k + 1
            break
        if abort_lateral_error_m is not None and abs(ey) > abort_lateral_error_m:
            aborted = True
            goal_reached = False
            k_end = k + 1
            break
    sl = slice(0, k_end)
    meta = dict(meta or {})
    if observed:
        meta["plant_state_final"] = [float(c) for c in xp]
    clearance = None
    if obstacles:
        clearance, meta["obstacles"] = _clearances(Xs[sl], T[sl], obstacles, footprint)
        meta["min_obstacle_clearance_m"] = float(clearance.min())
        hit = clearance < 0.0
        meta["collisions"] = int(np.count_nonzero(hit[1:] & ~hit[:-1]) + (1 if hit[0] else 0))
    v = model.speed(Xs[sl])
    steer = Us[sl, 0]
    accel = Us[sl, list(model.input_names).index("accel")] if "accel" in model.input_names else np.zeros(k_end)
    return SimResult(
        t_s=T[sl].copy(),
        x=Xs[sl].copy(),
        u=Us[sl].copy(),
        x_final=x,
        s_m=S[sl].copy(),
        e_y_m=EY[sl].copy(),
        e_psi_rad=EPSI[sl].copy(),
        yaw_rad=Xs[sl, 2].copy(),
        v_mps=np.asarray(v, float),
        steer_rad=steer.copy(),
        accel_mps2=np.asarray(accel, float).copy(),
        X_pred=XP[sl].copy(),
        refs=RF[sl].copy(),
        status=tuple(status),
        fallback=tuple(fallback),
        solve_time_s=ST[sl].copy(),
        path_xy=path.polyline(),
        dt_s=float(dt_s),
        state_names=tuple(model.state_names),
        input_names=tuple(model.input_names),
        lane_half_width_m=lane_half_width_m,
        goal_reached=goal_reached,
        meta={**meta, "termination": termination, **({"aborted_off_path": True} if aborted else {})},
        clearance_m=clearance,
    )


def _clearances(X: np.ndarray, T: np.ndarray, obstacles, footprint: Footprint):
    """(K,) smallest footprint-to-obstacle signed distance per step [m], and the obstacles'
    logged shapes and poses (for reports)."""
    K = len(T)
    clear = np.full(K, np.inf)
    logs = []
    for ob in obstacles:
        poses = np.array([ob.pose_at(t) for t in T])
        for k in range(K):
            d = shape_distance(footprint.polygon(*X[k, :3]), ob.at(T[k]))
            clear[k] = min(clear[k], d)
        entry = {"name": ob.name, "moving": ob.moving}
        if isinstance(ob.shape, Circle):
            centers = poses[:, :2].round(4)
            entry.update(type="circle", radius_m=ob.shape.radius_m,
                         center=centers.tolist() if ob.moving else centers[0].tolist())
        else:
            world = np.array([ob.at(t).points for t in (T if ob.moving else T[:1])]).round(4)
            entry.update(type="polygon", points=world.tolist() if ob.moving else world[0].tolist())
        logs.append(entry)
    return clear, logs
