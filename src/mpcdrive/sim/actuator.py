"""Steering actuator: dead time, then a first-order lag.

A steering command issued at time ``t`` reaches the actuator at ``t + dead_time_s``; the wheel
angle then follows it as ``delta' = (command - delta) / time_constant_s`` (instantly when the
time constant is 0). The simulator advances the actuator in the plant's substeps (so dead times
are resolved to a substep) and applies the mean wheel angle over each substep; a controller can
run the same model forward to compensate the delay (:class:`~mpcdrive.control.delay.DelayCompensator`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

_EPS_T = 1e-9  # s, tolerance on time comparisons


@dataclass(frozen=True)
class ActuatorState:
    """Wheel angle ``steer_rad`` [rad] now and the commands issued but not yet superseded:
    ``history`` of (issue time [s], command [rad]), oldest first; ``idle_command_rad`` acts before
    any command arrives."""

    steer_rad: float
    history: tuple[tuple[float, float], ...] = ()
    idle_command_rad: float = 0.0

    def issue(self, t_s: float, command_rad: float) -> ActuatorState:
        """The state after sending ``command_rad`` at time ``t_s``."""
        if not math.isfinite(command_rad):
            raise ValueError(f"steering command must be finite, got {command_rad}")
        return ActuatorState(self.steer_rad, self.history + ((float(t_s), float(command_rad)),), self.idle_command_rad)


@dataclass(frozen=True)
class SteeringActuator:
    """time_constant_s : first-order lag [s] (0: none); dead_time_s : transport delay [s] (0: none)."""

    time_constant_s: float = 0.0
    dead_time_s: float = 0.0

    def __post_init__(self):
        for name in ("time_constant_s", "dead_time_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v}")

    @property
    def is_ideal(self) -> bool:
        return self.time_constant_s == 0 and self.dead_time_s == 0

    def start(self, steer_rad: float = 0.0) -> ActuatorState:
        """Initial state: wheels at ``steer_rad`` [rad], holding it until the first command arrives."""
        return ActuatorState(float(steer_rad), (), float(steer_rad))

    def effective_command(self, state: ActuatorState, t_s: float) -> float:
        """The command acting on the actuator at time ``t_s`` [s] (the last one issued at or before
        ``t_s - dead_time_s``)."""
        cmd = state.idle_command_rad
        for t_issue, c in state.history:
            if t_issue + self.dead_time_s <= t_s + _EPS_T:
                cmd = c
            else:
                break
        return cmd

    def advance(self, state: ActuatorState, t_s: float, h_s: float) -> tuple[float, ActuatorState]:
        """Advance from ``t_s`` over ``h_s`` [s] with the command acting at ``t_s``; returns
        (mean wheel angle over the interval [rad], new state)."""
        c = self.effective_command(state, t_s)
        d0 = state.steer_rad
        T = self.time_constant_s
        if T <= 0:
            mean, d1 = c, c
        else:
            e = math.exp(-h_s / T)
            d1 = c + (d0 - c) * e
            mean = c + (d0 - c) * (T / h_s) * (1.0 - e)
        # forget commands superseded by a later one that is already acting
        hist = state.history
        t_next = t_s + h_s
        while len(hist) > 1 and hist[1][0] + self.dead_time_s <= t_next + _EPS_T:
            hist = hist[1:]
        return mean, ActuatorState(d1, hist, state.idle_command_rad)
