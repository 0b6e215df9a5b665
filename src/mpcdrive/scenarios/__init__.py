"""Scenario files (YAML, validated by pydantic) and the built-in experiments."""

from .build import Experiment, PlantFactory, build_experiment, run_experiment
from .loader import (
    ScenarioError,
    builtin_ids,
    dump_scenario,
    load_scenario,
    reject_initial_overlap,
    validate_scenario_data,
    warn_suspicious,
)
from .schema import ScenarioSpec

__all__ = [
    "Experiment",
    "PlantFactory",
    "ScenarioError",
    "ScenarioSpec",
    "build_experiment",
    "builtin_ids",
    "dump_scenario",
    "load_scenario",
    "reject_initial_overlap",
    "run_experiment",
    "validate_scenario_data",
    "warn_suspicious",
]
