"""Closed loop: a controller drives a plant model (possibly different from its own model)."""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from ..control.base import Controller
from ..models.base import VehicleModel
from ..models.discretize import Method, discrete_step
from ..paths.base import ReferencePath
from ..scene.footprint import Footprint
from ..scene.obstacles import Obstacle
from ..scene.road import Road
from ..scene.world import Scene
from ..types import STATUS_HELD, SimResult
from .actuator import ActuatorState, SteeringActuator
from .contact import clearances, collision_events, contact_count, recorded_traffic


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
            raise ValueError(
                f"plant model must be a vehicle model (f, jacobians, speed, ...), got {type(self.model).__name__}"
            )
        if self.method not in ("rk4", "euler"):
            raise ValueError(f"plant method must be 'rk4' or 'euler', got {self.method!r}")
        if isinstance(self.substeps, bool) or not isinstance(self.substeps, numbers.Integral) or self.substeps < 1:
            raise ValueError(f"plant substeps must be an integer >= 1, got {self.substeps!r}")

    def step(self, x: np.ndarray, u: np.ndarray, dt_s: float) -> np.ndarray:
        h = dt_s / self.substeps
        for _ in range(self.substeps):
            x = discrete_step(self.model, x, u, h, self.method)
        return x

    def step_actuated(
        self, x: np.ndarray, u: np.ndarray, dt_s: float, act: ActuatorState, t_s: float
    ) -> tuple[np.ndarray, ActuatorState]:
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


@runtime_checkable
class TrafficPlant(Protocol):
    """A plant with traffic of its own (another simulator's vehicles), which it moves itself.

    traffic(t_s) : the obstacles as they are at the loop's time ``t_s`` [s] (``pose_at(t_s)``
    their current poses, later times their predictions), always the same number in the same
    order (index = identity).
    """

    def traffic(self, t_s: float) -> tuple[Obstacle, ...]: ...


@runtime_checkable
class EpisodicPlant(Protocol):
    """A plant whose episode can end (another simulator's termination).

    ended(xp) : after a step to plant state ``xp``, why the episode is over (a short reason,
    :data:`ENDED_COLLISION` for a contact the plant found itself), or None while it goes on.
    """

    def ended(self, xp: np.ndarray) -> str | None: ...


#: the reason a plant that checks contacts itself gives for ending the episode
ENDED_COLLISION = "collision"


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


def _check_run_args(dt_s, steps, seed) -> None:
    if isinstance(dt_s, bool) or not isinstance(dt_s, numbers.Real) or not (math.isfinite(dt_s) and dt_s > 0):
        raise ValueError(f"dt_s must be a positive finite number, got {dt_s!r}")
    if isinstance(steps, bool) or not isinstance(steps, numbers.Integral) or steps < 1:
        raise ValueError(f"steps must be an integer >= 1, got {steps!r}")
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")


def judged_scene(
    controller,
    scene: Scene | None = None,
    road: Road | None = None,
    obstacles: tuple[Obstacle, ...] | None = None,
    footprint: Footprint | None = None,
) -> Scene:
    """The scene a drive of ``controller`` is judged against: the controller's own
    (``controller.scene``, or that of the controller it wraps), or the one given, which must then
    be the same world (a ValueError naming what differs). The older arguments ``road``,
    ``obstacles``, ``footprint`` name parts of it (the rest is the controller's); a controller
    without a scene (a baseline) is judged against what is given (nothing: an empty scene)."""
    own = inner_attr(controller, "scene")
    if own is not None and not isinstance(own, Scene):
        raise ValueError(f"the controller's scene must be a mpcdrive.scene.Scene, got {type(own).__name__}")
    parts = {"road": road, "obstacles": obstacles, "footprint": footprint}
    named = {k: v for k, v in parts.items() if v is not None}
    if scene is not None and not isinstance(scene, Scene):
        raise ValueError(f"scene must be a mpcdrive.scene.Scene or None, got {type(scene).__name__}")
    if scene is not None and named:
        raise ValueError(f"give the scene or its parts ({', '.join(named)}), not both")
    if road is not None and not isinstance(road, Road):
        raise ValueError(f"road must be a mpcdrive.scene.Road or None, got {type(road).__name__}")
    if named:
        base = own if own is not None else Scene()
        scene = dataclasses.replace(base, **{k: tuple(v) if k == "obstacles" else v for k, v in named.items()})
    if scene is None:
        return own if own is not None else Scene()
    if own is not None:
        diff = own.differences(scene)
        if diff:
            raise ValueError(
                "the scene given to simulate is not the controller's (controller.scene): "
                + "; ".join(diff)
                + " (controller's vs given); build the controller with the scene and leave it out here"
            )
    return scene


#: ways to drive the plant between two solves of a controller slower than the plant
BETWEEN_SOLVES = ("hold", "plan")


def solve_interval(dt_s: float, control_period_s: float | None, name: str = "control_period_s") -> int:
    """Plant steps per controller period: ``control_period_s / dt_s`` as a whole number (1 for
    None); ValueError naming both (the period as ``name``) when the period is not a positive
    whole multiple of ``dt_s`` within rounding (a relative 1e-9)."""
    if control_period_s is None:
        return 1
    p = control_period_s
    if isinstance(p, bool) or not isinstance(p, numbers.Real) or not (math.isfinite(p) and p > 0):
        raise ValueError(f"{name} must be a positive finite number, got {p!r}")
    ratio = p / dt_s
    m = int(round(ratio))
    if m < 1:
        raise ValueError(
            f"{name} {p:g} s is shorter than the plant step dt_s {dt_s:g} s; "
            "the controller cannot run faster than the plant"
        )
    if abs(ratio - m) > 1e-9 * ratio:
        raise ValueError(
            f"{name} {p:g} s is not a whole multiple of the plant step dt_s {dt_s:g} s ({ratio:.6g} plant steps)"
        )
    return m


def inner_attr(controller, name: str):
    """Attribute ``name`` of ``controller`` or, if it has none, of the controller it wraps
    (``inner``, as the state adapter, the delay compensator and the predicting controller do;
    up to 8 deep); None if none has it."""
    c = controller
    for _ in range(8):
        if c is None:
            return None
        value = getattr(c, name, None)
        if value is not None:
            return value
        c = getattr(c, "inner", None)
    return None


def _horizon_step_s(controller) -> float | None:
    """The horizon step [s] of ``controller`` (or of the controller it wraps), None if unknown."""
    dt = inner_attr(controller, "dt_s")
    return float(dt) if isinstance(dt, numbers.Real) and not isinstance(dt, bool) else None


def steering_meta(controller, plant) -> dict:
    """What the run's steering could do, for the metrics: ``steer_limits_rad`` (the controller's
    steering bounds ``(lo, hi)`` [rad]) and ``steer_rate_limit_rad_s`` (its steering-rate limit
    [rad/s], None for none) from its problem (or the problem of the controller it wraps; neither
    key without one), and ``steering_actuator``, the plant's (a :class:`SteeringActuator`; ideal
    without one; not recorded for an observed plant, which steers itself)."""
    meta: dict = {}
    pb = inner_attr(controller, "problem")
    lo, hi = getattr(pb, "u_min", None), getattr(pb, "u_max", None)
    if lo is not None and hi is not None:
        meta["steer_limits_rad"] = (float(lo[0]), float(hi[0]))
        du = getattr(pb, "du_max_per_s", None)
        rate = math.inf if du is None else float(np.asarray(du, float).reshape(-1)[0])
        meta["steer_rate_limit_rad_s"] = None if rate == math.inf else rate
    if isinstance(plant, Plant):
        meta["steering_actuator"] = plant.actuator if plant.actuator is not None else SteeringActuator()
    return meta


def _plan_slope(controller, out, nu: int) -> np.ndarray | None:
    """(nu,) change of the input over one controller period along the plan of ``out``: from the
    applied command to the plan's second input (clipped to the controller's input bounds when it
    has them); None when the command did not come with a plan of two or more finite inputs."""
    U = getattr(out.warm, "U", None)
    if U is None:
        return None
    U = np.asarray(U, float)
    if U.ndim != 2 or U.shape[0] < 2 or U.shape[1] != nu or not np.all(np.isfinite(U[1])):
        return None
    u1 = U[1]
    pb = inner_attr(controller, "problem")
    lo, hi = getattr(pb, "u_min", None), getattr(pb, "u_max", None)
    if lo is not None and hi is not None:
        u1 = np.clip(u1, lo, hi)
    return u1 - np.asarray(out.u, float)


def simulate(
    controller: Controller,
    plant: Plant | ObservedPlant,
    path: ReferencePath,
    x0,
    dt_s: float,
    steps: int,
    *,
    disturbance: Disturbance | None = None,
    measurement_noise: Disturbance | None = None,
    seed: int = 0,
    stop_at_path_end: bool = True,
    scene: Scene | None = None,
    road: Road | None = None,
    progress: Callable[[int, int], None] | None = None,
    meta: dict | None = None,
    obstacles: tuple[Obstacle, ...] | None = None,
    footprint: Footprint | None = None,
    laps: float | None = None,
    abort_lateral_error_m: float | None = None,
    control_period_s: float | None = None,
    between_solves: str = "hold",
) -> SimResult:
    """Run ``steps`` plant steps of ``dt_s`` seconds from ``x0`` (plant state).

    The controller is called every ``control_period_s / dt_s`` plant steps (``control_period_s``:
    a whole multiple of ``dt_s``; None = ``dt_s``, a solve at every step) and must be built with
    that period as its horizon step (its ``dt_s``; ValueError otherwise). Between two solves the
    plant gets, per ``between_solves``:

    * ``hold`` (zero-order hold): the command of the last solve at every plant step until the
      next solve, the input the controller's prediction assumes;
    * ``plan``: the plan followed in time, linearly interpolated: at the j-th plant step after a
      solve (j = 0 .. m - 1, m plant steps per period) ``u + (j / m) (U[1] - u)``, ``u`` the
      solve's command (``U[0]`` within the bounds) and ``U[1]`` the plan's input for the next
      controller interval (clipped to the controller's input bounds); the input ramps towards
      where the plan goes instead of stepping at each solve. A command without such a plan
      (a ``brake`` or ``hold_last`` fallback, a horizon of 1) is held. A steering-delay
      compensator, which predicts with held commands, needs ``hold``.

    Every plant step is logged: on the steps between solves ``status`` is ``held``
    (:data:`~mpcdrive.types.STATUS_HELD`), ``fallback`` empty, ``solve_time_s`` 0, the plan and
    references those of the last solve, and the path coordinates the true state's own
    projection; the metrics count only real solves. The measurement noise is drawn only when the
    controller measures (at solves); the disturbance at every plant step. With the period equal
    to ``dt_s`` the run is the one-solve-per-step loop, bit for bit.

    The controller sees the plant state plus ``measurement_noise``; the plant state receives
    ``disturbance`` after every step. On an open path the run ends when the vehicle passes the
    path's end (``stop_at_path_end``), and ``goal_reached`` says whether it did.
    ``progress(k, steps)`` is called every step when given.

    The drive is judged against the world it happens in, the scene (:func:`judged_scene`): the
    controller's own (``controller.scene``; an ``LtvMpc`` built with ``scene=``, or with the road
    in its problem and ``obstacles=`` / ``footprint=``; wrappers are looked through), so it cannot
    be forgotten. A ``scene`` given here must be that same world (a ValueError names what
    differs); ``road`` / ``obstacles`` / ``footprint`` name parts of it, the older way. Only a
    controller without a scene (a baseline) takes its scene from here. With a road the body's
    excess outside the whole road (every lane: :meth:`Scene.judged_road`) is measured at each
    step, exactly (``SimResult.lane_excess_m``, :meth:`Road.measure_excess_m`, 0 inside); a road
    that begins or ends along the path adds the ends' share of it, how far the body reached
    behind its start or past its end, in ``meta["road_end_excess_m"]``. With obstacles the
    signed distance between the body and every obstacle is measured at each step and, where
    they may meet in between, on the swept motion between the steps
    (:mod:`mpcdrive.sim.contact`): ``SimResult.clearance_m`` at the logged steps (negative =
    overlap), the obstacles' poses in ``meta["obstacles"]``, the number of contacts in
    ``meta["collisions"]``, each contact (which obstacle, when it began, how deep; also one
    between two logged steps) in ``meta["collision_events"]``
    (:func:`~mpcdrive.sim.contact.collision_events`) and the smallest distance, contacts between
    the steps included, in ``meta["min_obstacle_clearance_m"]``.
    On a closed path, ``laps`` ends the
    run once the vehicle has driven that many laps from its start (``goal_reached`` says whether
    it did within ``steps``). ``abort_lateral_error_m`` ends the run early when the lateral error
    exceeds it (the car left the road; ``goal_reached`` is then False and
    ``meta["aborted_off_path"]`` True).

    An :class:`ObservedPlant` starts from ``initial_state(x0)`` and is seen (by the controller,
    the log and the metrics) as ``observe(plant state)``; its own state at each logged step is
    ``meta["plant_states"]`` (K, n) and the one after the last step ``meta["plant_state_final"]``;
    state ``disturbance`` needs a :class:`Plant`.

    A :class:`TrafficPlant` (another simulator's vehicles) is asked for its ``traffic`` at every
    step; at each solve the controller gets the scene's obstacles followed by the traffic
    (``controller.set_obstacles``, when it has the method and there is traffic), and the
    traffic's poses at each step, as the plant reported them, join the scene's obstacles in the
    clearance and collision accounting (indices after theirs). An :class:`EpisodicPlant`
    ends the run after the step at which ``ended`` gives a reason: ``meta["termination"]`` is
    that reason, and a plant-found contact (:data:`ENDED_COLLISION`) counts as a collision
    (``meta["collisions"]`` at least 1) even when no logged state overlaps.

    Invalid arguments raise ValueError naming the argument. A plant state that stops being finite
    ends the run early (``meta["termination"] = "diverged"``, the last finite state as
    ``x_final``); otherwise ``termination`` says how the run ended: ``path_end_reached`` (an
    open path's end), ``laps_completed``, ``aborted_off_path``, the reason an episodic plant
    gave, or ``completed`` (it ran its ``steps``) -- how it ended, not whether the goal was met
    (the metrics' verdict judges that). ``meta`` also records what the steering could do
    (:func:`steering_meta`) and the footprint's width (``footprint_width_m``).
    """
    _check_run_args(dt_s, steps, seed)
    world = judged_scene(controller, scene, road, obstacles, footprint)
    obstacles, footprint = world.obstacles, world.footprint
    m = solve_interval(dt_s, control_period_s)
    if between_solves not in BETWEEN_SOLVES:
        raise ValueError(f"between_solves must be 'hold' or 'plan', got {between_solves!r}")
    h = _horizon_step_s(controller)
    if m > 1 and h is not None and abs(h - control_period_s) > 1e-9 * control_period_s:
        raise ValueError(
            f"the controller's horizon step dt_s {h:g} s differs from control_period_s "
            f"{control_period_s:g} s: build the controller with dt_s = the control period"
        )
    observed = not isinstance(plant, Plant)
    if observed and not isinstance(plant, ObservedPlant):
        raise ValueError(f"plant must be a Plant or an ObservedPlant, got {type(plant).__name__}")
    if observed and disturbance is not None:
        raise ValueError("a state disturbance needs a Plant (an ObservedPlant's state has its own layout)")
    if not isinstance(path, ReferencePath):
        raise ValueError(f"path must be a ReferencePath, got {type(path).__name__}")
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
        raise ValueError(
            f"initial state x0 field(s) {', '.join(bad)} not finite: {dict(zip(model.state_names, x.tolist()))}"
        )
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
    plant_log: list[np.ndarray] = []  # an observed plant's own state at each logged step
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
    slope = None  # input change over one period along the plan (between_solves "plan")
    has_traffic = isinstance(plant, TrafficPlant)
    episodic = isinstance(plant, EpisodicPlant)
    set_obstacles = getattr(controller, "set_obstacles", None)
    traffic_log: list[tuple[Obstacle, ...]] = []  # the plant's traffic at each step
    seen: tuple[Obstacle, ...] = ()
    for k in range(steps):
        j = k % m  # plant steps since the last solve
        if has_traffic:
            seen = _traffic(plant, k * dt_s, traffic_log)
        if j == 0:
            if seen and set_obstacles is not None:
                set_obstacles((*obstacles, *seen))
            meas = x if measurement_noise is None else x + measurement_noise.sample(rng, nx)
            out = controller.step(meas, warm)
            warm = out.warm
            # Frenet coordinates of the true state (the controller's are of the measurement)
            if measurement_noise is None:
                s, ey, epsi = out.s_m, out.e_y_m, out.e_psi_rad
            else:
                fr = path.frenet(x[:3], out.s_m)
                s, ey, epsi = fr.s_m, fr.e_y_m, fr.e_psi_rad
            u = out.u
            if m > 1 and between_solves == "plan":
                slope = _plan_slope(controller, out, nu)
            ST[k] = out.solve_time_s
            status.append(out.status)
            fallback.append(out.fallback)
        else:
            fr = path.frenet(x[:3], S[k - 1])
            s, ey, epsi = fr.s_m, fr.e_y_m, fr.e_psi_rad
            u = out.u if slope is None else out.u + (j / m) * slope
            ST[k] = 0.0
            status.append(STATUS_HELD)
            fallback.append("")
        T[k], Xs[k], Us[k] = k * dt_s, x, u
        S[k], EY[k], EPSI[k] = s, ey, epsi
        XP[k], RF[k] = out.X_pred, out.refs
        if observed:
            plant_log.append(np.array(xp, float))
            xp_next = np.asarray(plant.step(xp, u, dt_s), float)
            x_next = np.asarray(plant.observe(xp_next), float) if np.all(np.isfinite(xp_next)) else xp_next
        elif act is None:
            x_next = plant.step(x, u, dt_s)
        else:
            act = act.issue(k * dt_s, float(u[0]))
            x_next, act = plant.step_actuated(x, u, dt_s, act, k * dt_s)
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
        reason = plant.ended(xp if observed else x) if episodic else None
        if reason:
            termination = str(reason)
            k_end = k + 1
            break
        if goal_reached is not None and s >= (path.length_m if s_goal is None else s_goal):
            goal_reached = True
            termination = "path_end_reached" if s_goal is None else "laps_completed"
            k_end = k + 1
            break
        if abort_lateral_error_m is not None and abs(ey) > abort_lateral_error_m:
            aborted = True
            termination = "aborted_off_path"
            goal_reached = False
            k_end = k + 1
            break
    sl = slice(0, k_end)
    meta = {**steering_meta(controller, plant), "footprint_width_m": footprint.width_m, **(meta or {})}
    if m > 1:
        meta.update(control_period_s=float(control_period_s), between_solves=between_solves)
    if observed:
        meta["plant_state_final"] = [float(c) for c in xp]
        #: (K, n) the plant's own state at each logged step (e.g. for a CommonRoad ST solution)
        meta["plant_states"] = np.array(plant_log[:k_end], float)
    clearance = None
    judged = (*obstacles, *recorded_traffic(traffic_log[:k_end], T[sl]))
    if judged:
        at_steps, swept, began, meta["obstacles"] = clearances(Xs[sl], T[sl], judged, footprint)
        clearance = at_steps.min(axis=0)  # at the logged steps
        nearest = swept.min(axis=0)  # with the contacts between them
        meta["min_obstacle_clearance_m"] = float(nearest.min())
        meta["collisions"] = contact_count(nearest)
        meta["collision_events"] = collision_events(swept, T[sl], judged, began)
    if termination == ENDED_COLLISION:
        meta["collisions"] = max(int(meta.get("collisions", 0)), 1)
    lane_excess = profile = None
    road = world.judged_road()
    if road is not None:
        lane_excess = road.measure_excess_m(path, Xs[sl], S[sl], footprint)
        profile = road.profile(path.length_m)
        if road.has_ends:  # (K,) the ends' share of the excess [m]
            meta["road_end_excess_m"] = road.measure_end_excess_m(path, Xs[sl], S[sl], footprint)
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
        road_profile=profile,
        lane_excess_m=lane_excess,
        goal_reached=goal_reached,
        meta={**meta, "termination": termination, **({"aborted_off_path": True} if aborted else {})},
        clearance_m=clearance,
    )


def _traffic(plant: TrafficPlant, t_s: float, log: list) -> tuple[Obstacle, ...]:
    """The plant's traffic at ``t_s`` [s], appended to ``log``; ValueError when it is not a tuple
    of obstacles or its number changes (an obstacle's index is its identity)."""
    seen = tuple(plant.traffic(t_s))
    for i, ob in enumerate(seen):
        if not isinstance(ob, Obstacle):
            raise ValueError(f"the plant's traffic[{i}] must be an Obstacle, got {type(ob).__name__}")
    if log and len(seen) != len(log[0]):
        raise ValueError(f"the plant's traffic changed from {len(log[0])} to {len(seen)} obstacles (index = identity)")
    log.append(seen)
    return seen
