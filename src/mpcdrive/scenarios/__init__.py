"""Scenario files (YAML, validated by pydantic) and the built-in experiments."""

from .build import Experiment, build_experiment, run_experiment
from .loader import ScenarioError, builtin_ids, dump_scenario, load_scenario
from .schema import ScenarioSpec

__all__ = [
    "ScenarioSpec",
    "ScenarioError",
    "load_scenario",
    "dump_scenario",
    "builtin_ids",
    "Experiment",
    "build_experiment",
    "run_experiment",
]
