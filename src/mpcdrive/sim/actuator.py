"""Steering actuator: dead time, then a rate-limited first-order lag.

A steering command issued at time ``t`` reaches the actuator at ``t + dead_time_s``; the wheel
angle then follows it as ``delta' = clip((command - delta) / time_constant_s, -max_rate_rad_s,
max_rate_rad_s)``: a servo that turns the wheels at up to its rate limit and, within
``max_rate_rad_s * time_constant_s`` of the command, settles on it exponentially. With no time
constant the wheels turn at the rate limit until they are there (the F1TENTH and CommonRoad
steering), with no rate limit either they follow the command instantly. The motion is integrated
exactly, also when a command starts acting inside an interval. The simulator advances the
actuator in the plant's substeps and applies the mean wheel angle over each substep; a controller
can run the same model forward to compensate the delay
(:class:`~mpcdrive.control.delay.DelayCompensator`).
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
    """time_constant_s : first-order lag [s] (0: none); dead_time_s : transport delay [s] (0: none);
    max_rate_rad_s : the fastest the wheels turn [rad/s] (inf: no limit)."""

    time_constant_s: float = 0.0
    dead_time_s: float = 0.0
    max_rate_rad_s: float = math.inf

    def __post_init__(self):
        for name in ("time_constant_s", "dead_time_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v}")
        r = self.max_rate_rad_s
        if math.isnan(r) or not r > 0:
            raise ValueError(f"max_rate_rad_s must be a number > 0 (inf: no limit), got {r}")

    @property
    def is_ideal(self) -> bool:
        """No lag, no dead time, no rate limit: the wheels follow every command at once."""
        return self.time_constant_s == 0 and self.dead_time_s == 0 and self.max_rate_rad_s == math.inf

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

    def _follow(self, d0: float, c: float, tau: float) -> tuple[float, float]:
        """Wheel angle after following command ``c`` [rad] for ``tau`` [s] from ``d0`` [rad], and
        the integral of the angle over that time [rad s] (exact)."""
        T, r = self.time_constant_s, self.max_rate_rad_s
        e0 = c - d0
        sign = 1.0 if e0 >= 0 else -1.0
        # at the rate limit while the lag would turn faster (|e| > r T), or until there (T = 0)
        t_ramp = 0.0 if r == math.inf else max(0.0, (abs(e0) - r * T) / r)
        if t_ramp >= tau:
            return d0 + sign * r * tau, d0 * tau + 0.5 * sign * r * tau * tau
        d1 = d0 + sign * r * t_ramp if t_ramp > 0 else d0
        area = d0 * t_ramp + 0.5 * sign * r * t_ramp * t_ramp if t_ramp > 0 else 0.0
        rest = tau - t_ramp
        if T <= 0:
            return c, area + c * rest
        e = math.exp(-rest / T)
        return c + (d1 - c) * e, area + c * rest + (d1 - c) * T * (1.0 - e)

    def advance(self, state: ActuatorState, t_s: float, h_s: float) -> tuple[float, ActuatorState]:
        """Advance from ``t_s`` over ``h_s`` [s]: the command acting at ``t_s``, and each command
        that starts acting inside the interval from its moment on; returns (mean wheel angle
        over the interval [rad], new state)."""
        T = self.time_constant_s
        t_next = t_s + h_s
        # the moments inside the interval at which another command starts acting
        switches = [
            (t_issue + self.dead_time_s, c)
            for t_issue, c in state.history
            if t_s + _EPS_T < t_issue + self.dead_time_s < t_next - _EPS_T
        ]
        d0 = state.steer_rad
        c = self.effective_command(state, t_s)
        if not switches and self.max_rate_rad_s == math.inf:  # the plain lag, in closed form
            if T <= 0:
                mean, d1 = c, c
            else:
                e = math.exp(-h_s / T)
                d1 = c + (d0 - c) * e
                mean = c + (d0 - c) * (T / h_s) * (1.0 - e)
        else:
            d1, area, t = d0, 0.0, t_s
            for t_switch, c_next in [*switches, (t_next, c)]:
                d1, a = self._follow(d1, c, t_switch - t)
                area += a
                t, c = t_switch, c_next
            mean = area / h_s
        # forget commands superseded by a later one that is already acting
        hist = state.history
        while len(hist) > 1 and hist[1][0] + self.dead_time_s <= t_next + _EPS_T:
            hist = hist[1:]
        return mean, ActuatorState(d1, hist, state.idle_command_rad)
