"""Predictions of other cars from what is observable now (:mod:`.predictor`), along lanes
(:mod:`.lanes`), handed to a controller in place of the others' futures (:mod:`.controller`)."""

from .controller import PredictingController
from .lanes import Lane, LaneMap, LaneMatch
from .predictor import LanePredictor, Observation, PredictionConfig, inflated, observe

__all__ = [
    "Lane",
    "LaneMap",
    "LaneMatch",
    "LanePredictor",
    "Observation",
    "PredictingController",
    "PredictionConfig",
    "inflated",
    "observe",
]
