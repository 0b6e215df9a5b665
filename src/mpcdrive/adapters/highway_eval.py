"""highway-env's ``highway-v0`` driven by the MPC with the maneuver planner, against
highway-env's own IDM/MOBIL driver on the same seeds (docs/highway.md). Needs the ``highway``
extra; ``python -m mpcdrive.adapters.highway_eval`` runs the 20-seed evaluation."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from ..control.base import TrackingWarmStart
from ..models.base import VehicleModel
from ..paths.base import ReferencePath
from ..scene.world import Scene
from ..sim.closed_loop import simulate
from ..sim.metrics import compute_metrics
from ..types import STATUS_OK, ControlOutput, SimResult, WarmStart
from .highway_env import DriverSettings, HighwayEnvMpcDriver, highway_config, highway_settings, straight_road
from .highway_plant import HighwayEnvPlant

__all__ = ["HighwayEpisode", "evaluate_highway", "highway_episode"]


@dataclass(frozen=True)
class HighwayEpisode:
    """One highway-v0 episode of one ego policy (``mpc`` or ``idm``).

    seed; steps : policy steps driven; crashed : the ego crashed; off_road_steps : steps with the
    ego off every lane; mean_speed_mps : its mean speed [m/s] over the steps; distance_m : how far
    it got [m]; lane_changes : changes of its highway lane; overtakes : vehicles that were ahead
    of it in its lane (within 60 m) and later more than a car length behind it. From the closed
    loop's accounting (:func:`~mpcdrive.sim.compute_metrics` of ``result``, the run's log):
    collisions (contacts with the other vehicles, or the environment's crash), max_lane_excess_m
    (the body's largest excess outside the road's four lanes [m]), solver_failures, fallbacks."""

    policy: str
    seed: int
    steps: int
    crashed: bool
    off_road_steps: int
    mean_speed_mps: float
    distance_m: float
    lane_changes: int
    overtakes: int
    collisions: int = 0
    max_lane_excess_m: float = 0.0
    solver_failures: int = 0
    fallbacks: int = 0
    result: SimResult | None = field(default=None, repr=False, compare=False)


def _idm_ego(env, target_speed_mps: float):
    """Replace the ego of a reset highway-env environment by highway-env's own ``IDMVehicle``
    (IDM car following, MOBIL lane changes) wanting ``target_speed_mps`` [m/s]; it ignores the
    actions given to ``env.step``."""
    from highway_env.vehicle.behavior import IDMVehicle

    u = env.unwrapped
    old = u.vehicle
    ego = IDMVehicle(u.road, old.position, old.heading, old.speed, target_speed=target_speed_mps)
    u.road.vehicles[u.road.vehicles.index(old)] = ego
    u.controlled_vehicles[0] = ego
    u.action_type.controlled_vehicle = ego
    return ego


class EnvDriven(TrackingWarmStart):
    """The controller of an ego that drives itself (highway-env's ``IDMVehicle``, which ignores
    the actions): it commands zeros, so the logged inputs are 0, not the vehicle's own. ``N = 0``:
    the "prediction" is the current state; path coordinates on ``path``."""

    name = "env-driven"
    N = 0

    def __init__(self, model: VehicleModel, path: ReferencePath, dt_s: float):
        self.model, self.path, self.dt_s = model, path, float(dt_s)
        self.nx, self.nu = model.nx, model.nu

    def step(self, x, warm: WarmStart) -> ControlOutput:
        t0 = time.perf_counter()
        x = self._check_state(x)
        fr = self.path.frenet(x[:3], warm.s_m, 10.0 + 3.0 * float(self.model.speed(x)) * self.dt_s)
        u = np.zeros(self.nu)
        new_warm = WarmStart(s_m=fr.s_m, u_prev=u, t_s=warm.t_s + self.dt_s)
        X = x[None, :].copy()
        return ControlOutput(
            u, STATUS_OK, "", time.perf_counter() - t0, fr.s_m, fr.e_y_m, fr.e_psi_rad, X, X.copy(), new_warm
        )


class _Overtakes:
    """Called after each ``env.step``: the vehicles that were ahead of the ego in its lane
    (within 60 m) and later more than a car length behind it."""

    def __init__(self):
        self.was_ahead: set[int] = set()
        self.passed: set[int] = set()

    def __call__(self, env) -> None:
        u = env.unwrapped
        ego = u.vehicle
        for o in u.road.vehicles:
            if o is ego:
                continue
            dx = float(o.position[0] - ego.position[0])
            if 0.0 < dx < 60.0 and o.lane_index[2] == ego.lane_index[2]:
                self.was_ahead.add(id(o))
            elif dx < -float(o.LENGTH) and id(o) in self.was_ahead:
                self.passed.add(id(o))


def highway_episode(
    env,
    seed: int,
    policy: Literal["mpc", "idm"] = "mpc",
    settings: DriverSettings | None = None,
    steps: int | None = None,
) -> HighwayEpisode:
    """Reset ``env`` (a highway-v0 made with :func:`highway_config`) with ``seed`` and drive its
    ego with ``policy``: ``mpc`` (:class:`HighwayEnvMpcDriver` with ``settings``, by default
    :func:`highway_settings`) or ``idm`` (highway-env's IDM/MOBIL vehicle wanting the same speed,
    the baseline), for ``steps`` policy steps (default: the episode's duration), through
    :func:`~mpcdrive.sim.simulate` with the environment as the plant and the road's four lanes
    as the road the run is judged on."""
    settings = settings or highway_settings()
    env.reset(seed=int(seed))
    u = env.unwrapped
    if steps is None:
        steps = int(round(float(u.config["duration"]) * float(u.config["policy_frequency"])))
    scene: Scene | None = None  # the MPC driver's own (driver.scene)
    if policy == "mpc":
        driver = HighwayEnvMpcDriver(env, settings)
        controller, plant, path = driver, driver.plant, driver.path
    elif policy == "idm":
        _idm_ego(env, settings.v_ref_mps)
        plant = HighwayEnvPlant(env, prediction="constant_velocity")  # the traffic only for the accounting
        road, path, _ = straight_road(u.road.network, plant.lane_index)
        controller = EnvDriven(plant.model, path, plant.dt_s)
        scene = Scene(road, (), plant.footprint)
    else:
        raise ValueError(f"policy must be 'mpc' or 'idm', got {policy!r}")
    plant.observer = overtakes = _Overtakes()
    x0 = float(u.vehicle.position[0])
    lane0 = u.vehicle.lane_index[2]
    result = simulate(
        controller,
        plant,
        path,
        plant.state(),
        plant.dt_s,
        int(steps),
        scene=scene,
        stop_at_path_end=False,
        meta={"id": f"highway-v0-{policy}-{int(seed)}"},
    )
    m = compute_metrics(result)
    lanes = [lane0, *(r.lane_index[2] for r in plant.records)]
    return HighwayEpisode(
        policy,
        int(seed),
        len(plant.records),
        bool(u.vehicle.crashed),
        sum(not r.on_road for r in plant.records),
        float(np.mean([r.speed_mps for r in plant.records])),
        float(u.vehicle.position[0]) - x0,
        int(np.count_nonzero(np.diff(lanes))),
        len(overtakes.passed),
        collisions=m.collisions,
        max_lane_excess_m=m.max_lane_excess_m,
        solver_failures=m.solver_failures,
        fallbacks=m.fallbacks,
        result=result,
    )


def evaluate_highway(
    seeds=range(20),
    *,
    duration_s: float = 40.0,
    policies=("mpc", "idm"),
    settings: DriverSettings | None = None,
    **env_config,
) -> dict:
    """highway-v0 (highway-env's default traffic unless ``env_config`` says otherwise) for each
    seed and policy (see :func:`highway_episode`): ``{policy: {"episodes": [...],
    "crashes", "off_road" (episodes with an off-road step), "mean_speed_mps" (over the
    episodes), "lane_changes", "overtakes", and the closed loop's accounting summed over the
    episodes: "collisions", "solver_failures", "fallbacks", and the largest
    "max_lane_excess_m"}}``. Needs highway-env."""
    import gymnasium as gym
    import highway_env  # noqa: F401  (registers the environments)

    out: dict = {}
    for policy in policies:
        env = gym.make("highway-v0", config=highway_config(duration_s=duration_s, **env_config))
        eps = [highway_episode(env, seed, policy, settings) for seed in seeds]
        env.close()
        out[policy] = {
            "episodes": eps,
            "crashes": sum(e.crashed for e in eps),
            "off_road": sum(e.off_road_steps > 0 for e in eps),
            "mean_speed_mps": float(np.mean([e.mean_speed_mps for e in eps])),
            "lane_changes": sum(e.lane_changes for e in eps),
            "overtakes": sum(e.overtakes for e in eps),
            "collisions": sum(e.collisions for e in eps),
            "max_lane_excess_m": max(e.max_lane_excess_m for e in eps),
            "solver_failures": sum(e.solver_failures for e in eps),
            "fallbacks": sum(e.fallbacks for e in eps),
        }
    return out


if __name__ == "__main__":  # python -m mpcdrive.adapters.highway_eval: the 20-seed evaluation
    import os

    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    for name, res in evaluate_highway().items():
        print(
            f"{name}: {res['crashes']} crashes, {res['off_road']} off road, mean speed "
            f"{res['mean_speed_mps']:.2f} m/s, {res['lane_changes']} lane changes, {res['overtakes']} overtakes; "
            f"{res['collisions']} collisions, max lane excess {res['max_lane_excess_m']:.3g} m, "
            f"{res['solver_failures']} failed solves, {res['fallbacks']} fallbacks"
        )
        for e in res["episodes"]:
            print("   ", e)
