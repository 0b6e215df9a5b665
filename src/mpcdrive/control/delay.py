"""Delay compensation: predict the state over a known actuator delay before solving.

A command computed now reaches the wheels only after the actuator's dead time; meanwhile the car
moves under the commands already sent. :class:`DelayCompensator` keeps those commands (and an
estimate of the wheel angle) in its warm start, integrates the controller's model forward over
the dead time with them, and hands the *predicted* state to the wrapped controller -- so the
command is computed for the moment it will act.

The other inputs (acceleration) act without delay in the plant; a command planned for the moment
``t + dead time`` must then not be applied at ``t``, so the compensator holds them back by the dead
time (rounded to whole control periods) and sends each when its moment comes: every input then
acts when the plan meant it to, and the prediction knows all inputs in flight.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

import numpy as np

from ..models.base import VehicleModel
from ..models.discretize import Method, discrete_step
from ..paths.base import ReferencePath
from ..types import ControlOutput, WarmStart
from .base import Controller


class ActuatorEstimate(Protocol):
    """The state of a steering actuator model: ``issue(t_s, command_rad)`` gives the state after
    sending a command [rad] at time ``t_s`` [s] (e.g. :class:`~mpcdrive.sim.ActuatorState`)."""

    def issue(self, t_s: float, command_rad: float) -> ActuatorEstimate: ...


S = TypeVar("S", bound=ActuatorEstimate)


class DelayedActuator(Protocol[S]):
    """A steering actuator with dead time ``dead_time_s`` [s] whose state ``S`` starts at a wheel
    angle [rad] and advances over ``h_s`` [s] from ``t_s`` [s], returning the mean wheel angle
    [rad] and the new state (e.g. :class:`~mpcdrive.sim.SteeringActuator`)."""

    @property
    def dead_time_s(self) -> float: ...

    def start(self, steer_rad: float = ...) -> S: ...

    def advance(self, state: S, t_s: float, h_s: float) -> tuple[float, S]: ...


@dataclass(frozen=True)
class DelayWarmStart(WarmStart):
    """Warm start of :class:`DelayCompensator`: the wrapped controller's warm start ``inner``, the
    actuator estimate ``actuator`` (commands in flight, wheel angle), the time ``t_s`` [s] and the
    non-steering inputs held back (``pending``, oldest first, one per control period)."""

    inner: WarmStart | None = None
    actuator: ActuatorEstimate | None = None
    t_s: float = 0.0
    pending: tuple = ()


class DelayCompensator:
    """Wrap ``inner`` (a controller on ``model``) to compensate the steering ``actuator``'s delay.

    actuator : the known actuator (an object with ``dead_time_s``, ``start()``, ``advance()``, such
    as :class:`~mpcdrive.sim.SteeringActuator`); dt_s : control period [s]; path : the reference
    path (the logged path errors are those of the measured state, not the prediction);
    substeps : integration steps per control period for the prediction.
    """

    def __init__(
        self,
        inner: Controller,
        model: VehicleModel,
        actuator: DelayedActuator[Any],
        dt_s: float,
        path: ReferencePath,
        *,
        method: Method = "rk4",
        substeps: int = 5,
        projection_window_m: float = 2.0,
    ):
        if (inner.nx, inner.nu) != (model.nx, model.nu):
            raise ValueError("the delay compensator's model must match the wrapped controller's (nx, nu)")
        if not (math.isfinite(dt_s) and dt_s > 0):
            raise ValueError(f"dt_s must be positive, got {dt_s}")
        if int(substeps) != substeps or substeps < 1:
            raise ValueError(f"substeps must be a positive integer, got {substeps}")
        self.inner, self.model, self.actuator, self.path = inner, model, actuator, path
        self.name = f"{getattr(inner, 'name', type(inner).__name__)}+delay-compensation"
        self.nx, self.nu, self.N = inner.nx, inner.nu, inner.N
        self.dt_s, self.method, self.substeps = float(dt_s), method, int(substeps)
        self.window_m = projection_window_m
        self.n_hold = int(round(float(actuator.dead_time_s) / self.dt_s))

    def initial_warm(self, x0) -> DelayWarmStart:
        w = self.inner.initial_warm(x0)
        pending = tuple(np.array(w.u_prev[1:], dtype=float) for _ in range(self.n_hold))
        return DelayWarmStart(
            s_m=w.s_m,
            u_prev=w.u_prev,
            X=w.X,
            U=w.U,
            inner=w,
            actuator=self.actuator.start(0.0),
            t_s=0.0,
            pending=pending,
        )

    def predict(self, x, warm: DelayWarmStart) -> np.ndarray:
        """State (nx,) expected when a command sent now starts to act (after the dead time),
        driving the model with the commands already in flight; other inputs hold their last value."""
        act, t = warm.actuator, warm.t_s
        dead = float(self.actuator.dead_time_s)
        x = np.asarray(x, float)
        if dead <= 0:
            return x
        h_nom = self.dt_s / self.substeps
        n = max(1, int(math.ceil(dead / h_nom - 1e-9)))
        h = dead / n
        u = np.array(warm.u_prev, dtype=float)
        for i in range(n):
            j = int((i * h + 1e-9) // self.dt_s)  # control period of this substep
            if j < len(warm.pending):
                u[1:] = warm.pending[j]
            u[0], act = self.actuator.advance(act, t + i * h, h)
            x = discrete_step(self.model, x, u, h, self.method)
        return x

    def step(self, x, warm: DelayWarmStart) -> ControlOutput:
        t0 = time.perf_counter()
        x = np.asarray(x, float)
        if not isinstance(warm, DelayWarmStart) or warm.inner is None or warm.actuator is None:
            raise ValueError(
                "warm must come from this DelayCompensator (initial_warm or a step's warm): "
                "it has no inner warm start or actuator estimate"
            )
        x_pred = self.predict(x, warm)
        out = self.inner.step(x_pred, warm.inner)
        # the actuator estimate after this step's command, at the next step's time
        act = warm.actuator.issue(warm.t_s, float(out.u[0]))
        h = self.dt_s / self.substeps
        for i in range(self.substeps):
            _, act = self.actuator.advance(act, warm.t_s + i * h, h)
        fr = self.path.frenet(x[:3], warm.s_m, self.window_m)
        iw = out.warm
        u = np.array(out.u, dtype=float)
        pending = warm.pending
        if self.n_hold:  # send the held-back inputs planned for now, hold the new ones
            u[1:] = pending[0]
            pending = pending[1:] + (np.array(out.u[1:], dtype=float),)
        new_warm = DelayWarmStart(
            s_m=fr.s_m,
            u_prev=iw.u_prev,
            X=iw.X,
            U=iw.U,
            inner=iw,
            actuator=act,
            t_s=warm.t_s + self.dt_s,
            pending=pending,
        )
        return dataclasses.replace(
            out,
            u=u,
            s_m=fr.s_m,
            e_y_m=fr.e_y_m,
            e_psi_rad=fr.e_psi_rad,
            warm=new_warm,
            solve_time_s=time.perf_counter() - t0,  # the whole step: the prediction too
        )
