"""Published vehicle parameter sets for the dynamic bicycle.

* ``f1tenth``: the 1:10 F1TENTH car as the F1TENTH gym simulator ships it (mass 3.74 kg, yaw
  inertia 0.04712 kg m^2, lf 0.15875 m, lr 0.17145 m, friction 1.0489, cornering stiffness
  coefficients C_Sf 4.718 / C_Sr 5.4562 per rad, CoG height 0.074 m, steering +-0.4189 rad at up to
  3.2 rad/s, acceleration up to 9.51 m/s^2 (falling as 1/v above v_switch 7.319 m/s), 0.58 m x 0.31 m).
* ``commonroad_ford_escort``, ``commonroad_bmw_320i``, ``commonroad_vw_vanagon``: the CommonRoad
  vehicle parameter sets 1, 2 and 3 (values in US units converted with 1 lbf = 4.4482216152605 N,
  1 ft = 0.3048 m as CommonRoad does). Their single-track model uses friction = p_dy1 = 1.0489,
  C_Sf = C_Sr = -p_ky1 / p_dy1 = 21.92 / 1.0489 per rad and the sprung-mass CoG height h_s.

Every preset uses the CommonRoad lateral magic-formula shape factors (C = p_cy1 = 1.3507,
E = p_ey1 = -0.0074722) for the Pacejka tire, with B = C_S / C.

Each preset also carries its steering system (:class:`SteeringSystem`: the rate at which the
wheels can turn, the actuator's lag and dead time), each value with its source;
:data:`DEFAULT_STEERING` is the steering of a vehicle that names no preset (the paper's 1:10 car,
an F1TENTH-class car: the F1TENTH steering).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .dynamic import DynamicParams

_LBF = 4.4482216152605  # N
_FT = 0.3048  # m
_SLUG = _LBF / _FT  # kg per lb s^2 / ft
_SLUG_FT2 = _LBF * _FT  # kg m^2 per lb ft s^2
_CR_MU = 1.0489
_CR_CS = 21.92 / 1.0489


@dataclass(frozen=True)
class SteeringSystem:
    """How a vehicle's wheels follow a steering command: after ``dead_time_s`` [s] the wheels turn
    towards the command at up to ``max_rate_rad_s`` [rad/s], through a first-order lag of
    ``time_constant_s`` [s] (0: none, a servo that turns at its rate limit until it is there);
    ``source``: where the numbers come from. The plant's steering actuator
    (:class:`~mpcdrive.sim.SteeringActuator`) and, by default, the controller's steering-rate
    limit are these numbers."""

    max_rate_rad_s: float
    time_constant_s: float
    dead_time_s: float
    source: str


#: F1TENTH gym (f1tenth/f1tenth_gym, gym/f110_gym/envs): the steering angle is a state driven by
#: the steering velocity, clipped to sv_max = 3.2 rad/s (vehicle parameters); a commanded angle
#: becomes that velocity by bang-bang control towards it (dynamic_models.pid: +-sv_max until
#: there), so no lag; RaceCar keeps each command in a steering buffer of 2 physics steps of
#: 0.01 s (base_classes.py, steer_buffer_size = 2, time_step = 0.01) before it acts: 0.02 s dead time
F1TENTH_STEERING = SteeringSystem(
    max_rate_rad_s=3.2,
    time_constant_s=0.0,
    dead_time_s=0.02,
    source="F1TENTH gym: sv_max 3.2 rad/s, bang-bang servo (no lag), steering buffer of 2 x 0.01 s",
)
#: CommonRoad vehicle models (vehicleModels_commonRoad.pdf, parameters_vehicle1-3): the steering
#: angle is a state whose input is the steering velocity, |v_delta| <= 0.4 rad/s for all three
#: vehicles; no actuator lag and no dead time in the model (the drivability checker judges the
#: drive on that model)
COMMONROAD_STEERING = SteeringSystem(
    max_rate_rad_s=0.4,
    time_constant_s=0.0,
    dead_time_s=0.0,
    source="CommonRoad vehicle models: steering velocity within +-0.4 rad/s, no actuator lag or dead time",
)


@dataclass(frozen=True)
class VehiclePreset:
    """A named vehicle: dynamic parameters plus actuator limits and body size (SI units).

    max_steer_rad [rad]; steering : the steering system (rate limit, lag, dead time, with their
    source); max_accel_mps2 [m/s^2] (absolute), v_switch_mps [m/s]: speed above which the forward
    acceleration limit falls as ``max_accel v_switch / v``; length_m, width_m [m]; source: where
    the numbers come from.
    """

    name: str
    description: str
    params: DynamicParams
    max_steer_rad: float
    steering: SteeringSystem
    max_accel_mps2: float
    v_switch_mps: float
    length_m: float
    width_m: float
    source: str

    @property
    def max_steer_rate_rad_s(self) -> float:
        """The steering-rate limit [rad/s] (``steering.max_rate_rad_s``)."""
        return self.steering.max_rate_rad_s

    def accel_limit_mps2(self, v_max_mps: float) -> float:
        """The largest forward acceleration [m/s^2] the vehicle reaches at every speed up to
        ``v_max_mps`` [m/s]: ``max_accel`` up to ``v_switch``, ``max_accel v_switch / v`` above it
        (CommonRoad's longitudinal limit), so ``max_accel min(1, v_switch / v_max)``."""
        return float(self.max_accel_mps2 * min(1.0, self.v_switch_mps / max(v_max_mps, 1e-9)))

    @property
    def min_turning_radius_m(self) -> float:
        """Kinematic turning radius of the rear axle at full lock, L / tan(max_steer) [m]."""
        return self.params.wheelbase_m / math.tan(self.max_steer_rad)


def _commonroad(num, name, description, m_slug, a_ft, b_ft, iz_slugft2, hs_ft, steer, v_switch, length, width):
    return VehiclePreset(
        name=name,
        description=description,
        params=DynamicParams(
            lf_m=a_ft * _FT,
            lr_m=b_ft * _FT,
            mass_kg=m_slug * _SLUG,
            yaw_inertia_kgm2=iz_slugft2 * _SLUG_FT2,
            friction=_CR_MU,
            cs_front_per_rad=_CR_CS,
            cs_rear_per_rad=_CR_CS,
            h_cg_m=hs_ft * _FT,
        ),
        max_steer_rad=steer,
        steering=COMMONROAD_STEERING,
        max_accel_mps2=11.5,
        v_switch_mps=v_switch,
        length_m=length,
        width_m=width,
        source=f"CommonRoad vehicle models, parameters_vehicle{num}",
    )


PRESETS: dict[str, VehiclePreset] = {
    "f1tenth": VehiclePreset(
        name="f1tenth",
        description="1:10 F1TENTH race car (F1TENTH gym defaults)",
        params=DynamicParams(),
        max_steer_rad=0.4189,
        steering=F1TENTH_STEERING,
        max_accel_mps2=9.51,
        v_switch_mps=7.319,
        length_m=0.58,
        width_m=0.31,
        source="F1TENTH gym default vehicle parameters",
    ),
    "commonroad_ford_escort": _commonroad(
        1,
        "commonroad_ford_escort",
        "Ford Escort (CommonRoad vehicle id 1)",
        84.0,
        2.9,
        4.95,
        1135.0,
        1.95,
        0.910,
        4.755,
        4.298,
        1.674,
    ),
    "commonroad_bmw_320i": _commonroad(
        2,
        "commonroad_bmw_320i",
        "BMW 320i (CommonRoad vehicle id 2)",
        74.91452,
        3.793293,
        4.667707,
        1321.416,
        2.01355,
        1.066,
        7.319,
        4.508,
        1.610,
    ),
    "commonroad_vw_vanagon": _commonroad(
        3,
        "commonroad_vw_vanagon",
        "VW Vanagon (CommonRoad vehicle id 3)",
        101.3367,
        3.775563,
        4.334437,
        1824.078,
        2.639405,
        1.023,
        7.824,
        4.569,
        1.844,
    ),
}


#: the steering of a vehicle that names no preset: the paper's car is a 1:10 F1TENTH-class car
#: (lf 0.17 m, lr 0.16 m; the vehicle defaults are the F1TENTH car's), so the F1TENTH steering
DEFAULT_STEERING = F1TENTH_STEERING


def steering_of(preset: str | None) -> SteeringSystem:
    """The steering system of the vehicle preset ``preset`` (:data:`DEFAULT_STEERING` for None)."""
    return DEFAULT_STEERING if preset is None else get_preset(preset).steering


def get_preset(name: str) -> VehiclePreset:
    """The preset called ``name``; ValueError listing the known names otherwise."""
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"unknown vehicle preset {name!r} (known: {', '.join(PRESETS)})") from None
