"""Controller wrappers: run a controller on a plant whose state layout differs from its model's
(model mismatch, e.g. kinematic MPC on a dynamic plant)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..models.base import VehicleModel
from ..models.convert import state_converter
from ..types import ControlOutput, WarmStart
from .base import Controller


class StateAdapter:
    """``inner`` (built on ``controller_model``) driving a plant with ``plant_model``'s states.

    Each step converts the measured plant state to the controller's layout (see
    :mod:`mpcdrive.models.convert`); the predictions and references it returns are converted back
    to the plant's layout for the log. Inputs must be the same (names and order).
    """

    def __init__(self, inner: Controller, controller_model: VehicleModel, plant_model: VehicleModel):
        if tuple(controller_model.input_names) != tuple(plant_model.input_names):
            raise ValueError(
                f"controller model inputs {controller_model.input_names} differ from the plant's "
                f"{plant_model.input_names}; a state adapter cannot map inputs"
            )
        self.inner = inner
        self.name = getattr(inner, "name", type(inner).__name__)
        self.nx, self.nu, self.N = plant_model.nx, inner.nu, inner.N
        self._to_ctrl = state_converter(plant_model, controller_model)
        self._to_plant = state_converter(controller_model, plant_model)

    def initial_warm(self, x0) -> WarmStart:
        return self.inner.initial_warm(self._to_ctrl(np.asarray(x0, float)))

    def step(self, x, warm: WarmStart) -> ControlOutput:
        out = self.inner.step(self._to_ctrl(np.asarray(x, float)), warm)
        return dataclasses.replace(out, X_pred=self._to_plant(out.X_pred), refs=self._to_plant(out.refs))
