"""How the tracking LTV-MPC builds its problem each step: :class:`MpcConfig`.

Its own module, below both implementations of :class:`~mpcdrive.control.mpc.LtvMpc` (the Python
assembly of :mod:`~mpcdrive.control.python_mpc`, the compiled one of
:mod:`~mpcdrive.control.compiled_mpc`) and below what says whether the compiled step covers a
configuration (:mod:`~mpcdrive.control.compiled_setup`), which all read it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from ..models.discretize import Method
from ..paths.reference import HorizonMode
from ..paths.speed_profile import SpeedReference
from .fallback import FallbackConfig


@dataclass(frozen=True)
class MpcConfig:
    """How the tracking MPC builds its problem each step.

    linearization : ``trajectory`` (along the previous plan, shifted) or ``paper`` (at the
        current state and previous input, frozen over the horizon, eqs. 9-12);
    discretization : ``rk4``, ``euler`` (the paper) or ``exp`` (linearize, then discretize exactly:
        stable for stiff models such as the dynamic bicycle) for the prediction model;
    horizon : ``arc_length`` (references spaced by the distance driven at the reference speed) or
        ``paper`` (fixed ``horizon_step_m`` per step, the authors' code);
    v_ref_mps : reference speed [m/s] (the model's constant speed for 3-state models when None);
    speed_profile : reference speed along the path instead of a constant: a
        :class:`~mpcdrive.paths.SpeedReference`, any object with ``speed(s_m) -> v_mps`` (e.g.
        :class:`~mpcdrive.paths.SpeedProfile`); each horizon step
        then gets the profile's speed at its arc length, and a model with an ``accel`` input gets
        the profile's acceleration as input reference;
    feedforward : ``curvature`` (steering reference = the model's steady-state steering on the
        path curvature, so R does not fight the turn, and yaw reference = path heading minus the
        steady-state slip angle, since the centre of gravity moves along yaw + beta) or ``none``
        (the paper: ``u' R u`` and the path heading as yaw reference);
    projection_window_m : half-width of the arc-length window searched around the last s [m];
    sqp_max_iterations : QPs per step: 1 is the real-time iteration (one QP on the model and
        obstacle terms linearized along the shifted previous plan); more re-linearize at each new
        solution until the inputs move less than ``sqp_tol`` [input units] or ``sqp_max_iterations``
        QPs ran: an iteration cap, so a closed loop gives the same numbers on every machine;
    sqp_max_time_s : real-time mode, opt-in (default None: off): no SQP iteration starts that
        would end past this much wall time [s] (judged by the last one's time). The number of QPs
        per step then depends on the machine's speed and load, and so does the closed loop: a
        setting for a car with a deadline, never for tests, reproductions or sweeps.
    prediction_substeps : integration substeps per control step in the prediction model (stiff
        models such as the dynamic bicycle need them at long steps).
    steer_weight_speed_mps : above this speed [m/s] the weights on the steering angle and on its
        change (its entries of ``R`` and ``Rc``) grow as ``(v / steer_weight_speed_mps)^4`` with the
        measured speed ``v``. A steering angle turns the car's heading ``v / L`` times as fast and
        moves it sideways with ``v^2 / L`` times its angle; on a lateral error that is a double
        integrator with gain ``v^2 / L``, whose optimal loop has the natural frequency
        ``(q / r)^(1/4) sqrt(v^2 / L)``, growing with ``v``: with ``r`` grown as ``v^4`` the lateral
        loop keeps the bandwidth it has at this speed. A plant whose yaw lags the kinematic
        model (tyres) then keeps its margin at speed. None (default): constant weights.
    fallback : what to do, in order, when a solve fails (:class:`~mpcdrive.control.fallback.FallbackConfig`).
    """

    linearization: Literal["trajectory", "paper"] = "trajectory"
    discretization: Method = "rk4"
    horizon: HorizonMode = "arc_length"
    horizon_step_m: float = 0.025
    v_ref_mps: float | None = None
    feedforward: Literal["curvature", "none"] = "curvature"
    projection_window_m: float = 2.0
    sqp_max_iterations: int = 1
    sqp_tol: float = 1e-4
    sqp_max_time_s: float | None = None
    speed_profile: SpeedReference | None = None
    prediction_substeps: int = 1
    steer_weight_speed_mps: float | None = None
    fallback: FallbackConfig = FallbackConfig()

    def __post_init__(self):
        if self.linearization not in ("trajectory", "paper"):
            raise ValueError(f"linearization must be 'trajectory' or 'paper', got {self.linearization!r}")
        if self.discretization not in ("rk4", "euler", "exp"):
            raise ValueError(f"discretization must be 'rk4', 'euler' or 'exp', got {self.discretization!r}")
        if self.horizon not in ("arc_length", "paper"):
            raise ValueError(f"horizon must be 'arc_length' or 'paper', got {self.horizon!r}")
        if self.sqp_max_iterations < 1:
            raise ValueError(f"sqp_max_iterations must be >= 1, got {self.sqp_max_iterations}")
        if self.sqp_max_time_s is not None and not (
            isinstance(self.sqp_max_time_s, (int, float))
            and not isinstance(self.sqp_max_time_s, bool)
            and math.isfinite(self.sqp_max_time_s)
            and self.sqp_max_time_s > 0
        ):
            raise ValueError(
                f"sqp_max_time_s must be None (no wall-time cap) or a positive time [s], got {self.sqp_max_time_s!r}"
            )
        if self.feedforward not in ("curvature", "none"):
            raise ValueError(f"feedforward must be 'curvature' or 'none', got {self.feedforward!r}")
        if self.speed_profile is not None and not callable(getattr(self.speed_profile, "speed", None)):
            raise ValueError("speed_profile must have a speed(s_m) method")
        if int(self.prediction_substeps) != self.prediction_substeps or self.prediction_substeps < 1:
            raise ValueError(f"prediction_substeps must be a positive integer, got {self.prediction_substeps}")
        for name in ("horizon_step_m", "projection_window_m"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive finite number, got {v!r}")
        if self.v_ref_mps is not None and not (
            isinstance(self.v_ref_mps, (int, float)) and math.isfinite(self.v_ref_mps)
        ):
            raise ValueError(f"v_ref_mps must be a finite number, got {self.v_ref_mps!r}")
        w = self.steer_weight_speed_mps
        if w is not None and not (
            isinstance(w, (int, float)) and not isinstance(w, bool) and math.isfinite(w) and w > 0
        ):
            raise ValueError(
                f"steer_weight_speed_mps must be None (constant weights) or a positive speed [m/s], got {w!r}"
            )
        if not isinstance(self.fallback, FallbackConfig):
            raise ValueError(f"fallback must be a FallbackConfig, got {type(self.fallback).__name__}")
