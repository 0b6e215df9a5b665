"""Every field of the core's configuration dataclasses is reachable from a scenario file: each
has its YAML key here, and setting that key changes the built controller's field."""

from __future__ import annotations

import dataclasses

import pytest

from mpcdrive.control.fallback import FallbackConfig
from mpcdrive.control.mpc import MpcConfig
from mpcdrive.ocp.avoidance import AvoidanceConfig
from mpcdrive.scenarios import build_experiment, load_scenario
from mpcdrive.solvers.osqp_backend import OsqpSettings

#: core field -> (YAML section, key, a value that differs from the default, how to read it back)
REACH = {
    (MpcConfig, "linearization"): ("controller", "linearization", "paper"),
    (MpcConfig, "discretization"): ("controller", "discretization", "euler"),
    (MpcConfig, "horizon"): ("controller", "horizon_reference", "paper"),
    (MpcConfig, "horizon_step_m"): ("controller", "horizon_step_m", 0.05),
    (MpcConfig, "v_ref_mps"): ("controller", "reference_speed_mps", 1.3),
    (MpcConfig, "feedforward"): ("controller", "feedforward", "none"),
    (MpcConfig, "projection_window_m"): ("controller", "projection_window_m", 3.5),
    (MpcConfig, "sqp_max_iterations"): ("avoidance", "sqp_max_iterations", 3),
    (MpcConfig, "sqp_tol"): ("avoidance", "sqp_tol", 1e-3),
    (MpcConfig, "sqp_max_time_s"): ("avoidance", "sqp_max_time_s", 0.2),
    (MpcConfig, "speed_profile"): ("controller", "speed_profile", {"v_max_mps": 1.5}),
    (MpcConfig, "prediction_substeps"): ("controller", "prediction_substeps", 2),
    (MpcConfig, "steer_weight_speed_mps"): ("controller", "steer_weight_speed_mps", 8.0),
    (MpcConfig, "fallback"): ("controller", "fallback", ["brake"]),
    (FallbackConfig, "ladder"): ("controller", "fallback", ["shifted_plan", "brake"]),
    (FallbackConfig, "brake_decel_mps2"): ("controller", "brake_decel_mps2", 0.7),
    (FallbackConfig, "brake_steering"): ("controller", "brake_steering", "straighten"),
    (FallbackConfig, "relax_slack_factor"): ("controller", "relax_slack_factor", 10.0),
    (FallbackConfig, "check_plans"): ("controller", "check_plans", False),
    (AvoidanceConfig, "formulation"): ("avoidance", "formulation", "corridor"),
    (AvoidanceConfig, "margin_m"): ("avoidance", "margin_m", 0.2),
    (AvoidanceConfig, "weight"): ("avoidance", "weight", 3.0),
    (AvoidanceConfig, "epsilon_m2"): ("avoidance", "epsilon_m2", 0.1),
    (AvoidanceConfig, "sigma_m"): ("avoidance", "sigma_m", [0.4, 0.6]),
    (AvoidanceConfig, "influence_m"): ("avoidance", "influence_m", 7.0),
    (AvoidanceConfig, "max_obstacles"): ("avoidance", "max_obstacles", 2),
    (AvoidanceConfig, "detour"): ("avoidance", "detour", "trapezoid"),
    (AvoidanceConfig, "detour_ramp_m"): ("avoidance", "detour_ramp_m", 2.0),
    (AvoidanceConfig, "follow_gap_s"): ("avoidance", "follow_gap_s", 1.2),
    (AvoidanceConfig, "follow_decel_mps2"): ("avoidance", "follow_decel_mps2", 2.0),
    (OsqpSettings, "eps_abs"): ("controller", "osqp_eps", 1e-4),
    (OsqpSettings, "eps_rel"): ("controller", "osqp_eps", 1e-4),
    (OsqpSettings, "max_iter"): ("controller", "osqp_max_iter", 555),
    (OsqpSettings, "polish"): ("controller", "osqp_polish", False),
    (OsqpSettings, "adaptive_rho"): ("controller", "osqp_adaptive_rho", False),
    (OsqpSettings, "time_limit_s"): ("controller", "osqp_time_limit_s", 0.5),
}


def test_every_core_field_has_a_yaml_key():
    for cls in (MpcConfig, FallbackConfig, AvoidanceConfig, OsqpSettings):
        missing = [f.name for f in dataclasses.fields(cls) if (cls, f.name) not in REACH]
        assert not missing, f"{cls.__name__} fields without a YAML key: {missing}"


def _core(exp, cls):
    mpc = exp.mpc
    if cls is MpcConfig:
        return mpc.config
    if cls is FallbackConfig:
        return mpc.config.fallback
    if cls is AvoidanceConfig:
        return mpc.avoidance.config
    return mpc.backend.settings


@pytest.mark.parametrize("key", list(REACH), ids=[f"{c.__name__}.{n}" for c, n in REACH])
def test_the_yaml_key_sets_the_field(key):
    cls, name = key
    section, yaml_key, value = REACH[key]
    spec = load_scenario("paper-exp5-hard")
    data = spec.model_dump(exclude_none=True)
    data["controller"]["backend"] = "osqp"  # the OSQP controller takes every setting
    if cls is MpcConfig and name == "v_ref_mps":
        data["vehicle"] = {"model": "kinematic4", "speed_mps": 1.0}
        data["controller"]["Q"], data["controller"]["R"] = [1, 1, 1, 1], [1, 1]
        data["controller"].pop("QN", None)
    if name == "speed_profile":
        data["vehicle"] = {"model": "kinematic4", "speed_mps": 1.0}
        data["controller"]["Q"], data["controller"]["R"] = [1, 1, 1, 1], [1, 1]
        data["controller"].pop("QN", None)
    if name == "formulation":
        data["avoidance"]["detour"] = "none"
    data[section].pop(yaml_key, None)
    base = build_experiment(type(spec).model_validate(data))  # the key at its default
    data[section][yaml_key] = value
    exp = build_experiment(type(spec).model_validate(data))
    got = getattr(_core(exp, cls), name)
    assert got != getattr(_core(base, cls), name), (name, got)
    if name not in ("speed_profile", "fallback", "ladder", "sigma_m"):
        assert got == (pytest.approx(value) if isinstance(value, float) else value)
