"""highway-env's ``highway-v0`` driven by the MPC with the lane decision layer, against
highway-env's own IDM/MOBIL driver on the same seeds (docs/highway.md). Needs the ``highway``
extra; ``python -m mpcdrive.adapters.highway_eval`` runs the 20-seed evaluation."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from .highway_env import DriverSettings, HighwayEnvMpcDriver, highway_config, highway_settings

__all__ = ["HighwayEpisode", "evaluate_highway", "highway_episode"]


@dataclass(frozen=True)
class HighwayEpisode:
    """One highway-v0 episode of one ego policy (``mpc`` or ``idm``).

    seed; steps : policy steps driven; crashed : the ego crashed; off_road_steps : steps with the
    ego off every lane; mean_speed_mps : its mean speed [m/s] over the steps; distance_m : how far
    it got [m]; lane_changes : changes of its highway lane; overtakes : vehicles that were ahead
    of it in its lane (within 60 m) and later more than a car length behind it."""

    policy: str
    seed: int
    steps: int
    crashed: bool
    off_road_steps: int
    mean_speed_mps: float
    distance_m: float
    lane_changes: int
    overtakes: int


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
    the baseline), for ``steps`` policy steps (default: the episode's duration)."""
    settings = settings or highway_settings()
    env.reset(seed=int(seed))
    u = env.unwrapped
    if steps is None:
        steps = int(round(float(u.config["duration"]) * float(u.config["policy_frequency"])))
    if policy == "mpc":
        driver: HighwayEnvMpcDriver | None = HighwayEnvMpcDriver(env, settings)
    elif policy == "idm":
        driver = None
        _idm_ego(env, settings.v_ref_mps)
    else:
        raise ValueError(f"policy must be 'mpc' or 'idm', got {policy!r}")
    idle = np.zeros(env.action_space.shape, dtype=np.float32)
    x0 = float(u.vehicle.position[0])
    speeds, off, lanes = [], 0, [u.vehicle.lane_index[2]]
    was_ahead: set[int] = set()
    passed: set[int] = set()
    for _ in range(int(steps)):
        action = driver.act()[0] if driver is not None else idle
        _, _, terminated, truncated, _ = env.step(action)
        ego = u.vehicle
        speeds.append(float(ego.speed))
        off += not ego.on_road
        lanes.append(ego.lane_index[2])
        for o in u.road.vehicles:
            if o is ego:
                continue
            dx = float(o.position[0] - ego.position[0])
            if 0.0 < dx < 60.0 and o.lane_index[2] == ego.lane_index[2]:
                was_ahead.add(id(o))
            elif dx < -float(o.LENGTH) and id(o) in was_ahead:
                passed.add(id(o))
        if terminated or truncated:
            break
    return HighwayEpisode(
        policy,
        int(seed),
        len(speeds),
        bool(u.vehicle.crashed),
        int(off),
        float(np.mean(speeds)),
        float(u.vehicle.position[0]) - x0,
        int(np.count_nonzero(np.diff(lanes))),
        len(passed),
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
    episodes), "lane_changes", "overtakes"}}``. Needs highway-env."""
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
        }
    return out


if __name__ == "__main__":  # python -m mpcdrive.adapters.highway_eval: the 20-seed evaluation
    import os

    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    for name, res in evaluate_highway().items():
        print(
            f"{name}: {res['crashes']} crashes, {res['off_road']} off road, mean speed "
            f"{res['mean_speed_mps']:.2f} m/s, {res['lane_changes']} lane changes, {res['overtakes']} overtakes"
        )
        for e in res["episodes"]:
            print("   ", e)
