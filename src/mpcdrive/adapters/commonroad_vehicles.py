"""CommonRoad's vehicle models as the simulated vehicle (the plant), and CommonRoad vehicles for
the controller.

Optional extra ``commonroad`` (the ``commonroad-vehicle-models`` package, ``vehiclemodels``);
imported lazily, only when a CommonRoad plant is built or a vehicle's parameters are read.

:class:`CommonRoadPlant` integrates the package's unmodified right-hand sides
``vehicle_dynamics_ks`` (kinematic single track, 5 states), ``vehicle_dynamics_st`` (single
track with linear tyres, 7 states) and ``vehicle_dynamics_mb`` (multi-body, 29 states) with the
parameter sets 1, 2, 3 (Ford Escort, BMW 320i, VW Vanagon); their input limits (steering angle
and steering velocity, longitudinal acceleration with its ``a_max v_switch / v`` fall-off above
``v_switch``, speed range) are applied by the right-hand sides themselves.

:func:`apply_vehicle` sets a scenario's controller vehicle and limits from a CommonRoad vehicle
(and, optionally, the plant), :func:`solution_vehicle_type` gives the vehicle's ``VehicleType``
for CommonRoad solution files.
"""

from __future__ import annotations

import math

import numpy as np

from ..models.kinematic import KinematicBicycle4, KinematicParams
from ..models.presets import get_preset
from .commonroad_goal import friction_accel


#: CommonRoad vehicle name -> parameter set number (``parameters_vehicle<N>``)
VEHICLES: dict[str, int] = {"ford_escort": 1, "bmw_320i": 2, "vw_vanagon": 3}
#: plant model name (scenario files) -> CommonRoad model
PLANT_MODELS: dict[str, str] = {"commonroad_ks": "ks", "commonroad_st": "st", "commonroad_mb": "mb"}
_SHORT = {short: name for name, short in PLANT_MODELS.items()}  # ks -> commonroad_ks, ...
_G = 9.81  # [m/s^2], as in vehiclemodels
#: RK4's stability interval on the negative real axis is |h lambda| <= 2.785; the plant keeps
#: h rho <= this (rho: spectral radius of the stiff block), leaving room for complex eigenvalues
_RK4_STABLE = 2.0
#: default longest substep [s]: MB's pose after a 6 s brake to a stop at full lock is within 2 mm
#: of a 0.25 ms integration at 1 ms (8 mm at 2 ms, 0.2 m at 5 ms, 1.4 m at 10 ms); KS / ST within
#: 0.03 mm at 10 ms
_DEFAULT_STEP_S = {"ks": 0.01, "st": 0.01, "mb": 1e-3}
#: below this |v_x| [m/s] CommonRoad's ST and MB use their kinematic branch
_KINEMATIC_BELOW = 0.1
#: hub speed [m/s] below which MB's wheel-mode bound stops growing (its substeps stop shrinking)
_MB_MIN_HUB_SPEED = 0.01
#: MB wheel slip from which the plant's anti-lock / traction control lowers the command, and at
#: which it takes it away (the longitudinal magic formula peaks near 0.15)
_MB_SLIP_ON, _MB_SLIP_OFF = 0.10, 0.20


def available() -> bool:
    """True when ``commonroad-vehicle-models`` (``vehiclemodels``) is installed."""
    try:
        import vehiclemodels  # noqa: F401
    except ImportError:
        return False
    return True


def _require():
    try:
        import vehiclemodels  # noqa: F401
    except ImportError:
        raise ValueError(
            "CommonRoad vehicle models need the commonroad extra: "
            "pip install 'mpcdrive[commonroad]' (package commonroad-vehicle-models)"
        ) from None


def _check_vehicle(vehicle: str) -> int:
    if vehicle not in VEHICLES:
        raise ValueError(f"unknown CommonRoad vehicle {vehicle!r} (known: {', '.join(VEHICLES)})")
    return VEHICLES[vehicle]


def vehicle_parameters(vehicle: str):
    """The ``vehiclemodels`` parameter set of ``vehicle`` (``ford_escort``, ``bmw_320i``,
    ``vw_vanagon``)."""
    num = _check_vehicle(vehicle)
    _require()
    from vehiclemodels.vehicle_parameters import setup_vehicle_parameters

    return setup_vehicle_parameters(vehicle_id=num)


def preset_name(vehicle: str) -> str:
    """The mpcdrive vehicle preset (``models.presets``) of a CommonRoad vehicle."""
    _check_vehicle(vehicle)
    return f"commonroad_{vehicle}"


def solution_vehicle_type(vehicle: str):
    """CommonRoad's ``VehicleType`` enum member of ``vehicle`` (for solution files)."""
    num = _check_vehicle(vehicle)
    try:
        from commonroad.common.solution import VehicleType
    except ImportError:
        raise ValueError(
            "CommonRoad solution files need the commonroad extra: pip install 'mpcdrive[commonroad]'"
        ) from None
    return VehicleType(num)


def apply_vehicle(spec, vehicle: str, plant: str | None = None):
    """``spec`` (a :class:`ScenarioSpec`) with the controller's vehicle and limits taken from the
    CommonRoad ``vehicle`` (``ford_escort``, ``bmw_320i``, ``vw_vanagon``) and, with ``plant``
    (``ks``, ``st``, ``mb``), the plant set to that CommonRoad model of the vehicle.

    Vehicle: the ``commonroad_<vehicle>`` preset (wheelbase split lf/lr, footprint length and
    width, the dynamic parameters); controller: steering limit, steering-rate limit, acceleration
    limits ``[-a_max, a_max min(1, v_switch / v_top)]`` with ``v_top`` the controller's upper speed
    limit (else the larger of the reference and initial speeds plus 2 m/s), and the upper speed
    limit capped at the vehicle's ``v_max``. The controller's model is kept (a ``kinematic4``
    controller is needed for a CommonRoad plant). ValueError for an unknown vehicle or plant."""
    from ..scenarios.schema import ScenarioSpec

    p = vehicle_parameters(vehicle)
    if plant is not None and plant not in _SHORT:
        raise ValueError(f"unknown CommonRoad plant model {plant!r} (known: {', '.join(_SHORT)})")
    data = spec.model_dump(mode="python", exclude_unset=True)
    veh = {
        k: v
        for k, v in spec.vehicle.model_dump(exclude_unset=True).items()
        if k in ("model", "speed_mps", "footprint_discs", "v_blend_low_mps", "v_blend_high_mps")
    }
    veh["preset"] = preset_name(vehicle)
    data["vehicle"] = veh
    c = spec.controller
    v_ref = c.reference_speed_mps if c.reference_speed_mps is not None else spec.vehicle.speed_mps
    v0 = spec.initial_state.v_mps if spec.initial_state.v_mps is not None else v_ref
    lon = p.longitudinal
    if c.speed_limits_mps is not None:
        s_lo, s_hi = c.speed_limits_mps[0], min(c.speed_limits_mps[1], float(lon.v_max))
        v_top = s_hi
    else:
        s_lo, s_hi = None, None
        v_top = max(v_ref, v0) + 2.0
    a_hi = get_preset(preset_name(vehicle)).accel_limit_mps2(v_top)  # its numbers are vehiclemodels' (tested)
    ctrl = dict(data["controller"])
    ctrl["max_steer_deg"] = math.degrees(min(float(p.steering.max), -float(p.steering.min)))
    ctrl["max_steer_rate_deg_s"] = math.degrees(min(float(p.steering.v_max), -float(p.steering.v_min)))
    ctrl["accel_limits_mps2"] = (-float(lon.a_max), a_hi)
    ctrl["friction_accel_mps2"] = friction_accel(float(lon.a_max))
    if s_hi is not None:
        ctrl["speed_limits_mps"] = (s_lo, s_hi)
    data["controller"] = ctrl
    if plant is not None:
        data["plant"] = {"model": _SHORT[plant], "vehicle": vehicle}
    elif spec.plant.model in PLANT_MODELS:
        data["plant"] = {**spec.plant.model_dump(exclude_unset=True), "vehicle": vehicle}
    return ScenarioSpec.model_validate(data)


def commonroad_plant(model: str, vehicle: str) -> CommonRoadPlant:
    """The CommonRoad plant ``model`` (``commonroad_ks | commonroad_st | commonroad_mb``) of the
    CommonRoad ``vehicle``: the ``plant_factory`` of :func:`mpcdrive.scenarios.build_experiment`
    (and :func:`mpcdrive.runs.run_into`) for scenarios on CommonRoad's vehicle models. ValueError
    naming the extra when it is not installed."""
    if not available():
        raise ValueError(
            f"plant.model {model} needs the commonroad extra: pip install 'mpcdrive[commonroad]' "
            "(package commonroad-vehicle-models)"
        )
    return CommonRoadPlant(PLANT_MODELS[model], vehicle)


class PlantModelError(RuntimeError):
    """A CommonRoad vehicle model's equations cannot be evaluated at the plant's state."""


class CommonRoadPlant:
    """CommonRoad vehicle model ``model`` (``ks``, ``st``, ``mb``) of ``vehicle`` as the plant of the
    closed loop (an :class:`mpcdrive.sim.closed_loop.ObservedPlant`).

    **Inputs.** CommonRoad's inputs are the steering *velocity* and the longitudinal acceleration;
    the controller commands a steering *angle* and an acceleration. A steering servo sits in
    between: it turns the wheels towards the commanded angle (clipped to the steering limits) at
    the vehicle's steering-velocity limit, and stops on it (rate-limited, no overshoot: within an
    integration substep ``h`` the steering velocity is ``clip((delta_cmd - delta) / h, v_min,
    v_max)``, held constant, so the angle lands exactly on the command). The acceleration command
    goes to the model as it is; its right-hand side applies CommonRoad's limits (``|a| <= a_max``,
    forward ``a <= a_max v_switch / v`` above ``v_switch``, the speed range). Brakes stop the car
    and hold it, never drive it backwards: a negative command is limited to ``-v / h`` within a
    substep (the speed reaches zero and stays there); the controllers here drive forwards only.

    **States.** KS: ``[x, y, delta, v, yaw]`` at the *rear axle* (``v`` its speed); ST
    ``[x, y, delta, v, yaw, yaw rate, slip angle]`` and MB (29 states, ``v_x`` at index 3 and
    ``v_y`` at index 10) at the *centre of gravity*. The loop observes ``[x, y, yaw, v]`` of the
    centre of gravity (the ``kinematic4`` layout, ``model``): KS ``x_cog = x_r + lr cos(yaw)``,
    ``v = v_r / cos(beta)`` with ``beta = atan(lr / L tan(delta))``; ST ``v`` as it is; MB
    ``v = hypot(v_x, v_y)``, below ``|v_x| = 0.1`` m/s ``v = v_x`` (there the model moves its pose
    kinematically with ``v_x``; its ``v_y`` is left to the suspension equations and may drift at
    standstill without moving the car). Initial states: the observed pose and speed with the
    wheels straight and (ST, MB) no yaw rate or slip, through the package's ``init_ks`` /
    ``init_st`` / ``init_mb``.

    **Integration.** Classical RK4 on substeps with the inputs held (the control period split
    into equal substeps no longer than ``max_step_s``, default 10 ms for KS and ST, 1 ms for MB),
    shortened where the model is stiff so
    that ``h rho <= 2`` (RK4 is stable for ``|h lambda| <= 2.785`` on the negative real axis):
    ST's yaw-rate / slip-angle block has eigenvalues growing as ``1 / v`` (spectral radius 2160 1/s at
    0.1 m/s for the BMW 320i), whose spectral radius ``rho`` is computed from the model's
    coefficients at each substep; below 0.1 m/s CommonRoad's ST switches to its kinematic model
    itself (not stiff). MB's tyre and suspension modes are held by its 1 ms step; its wheel-spin
    modes, ``~R_w^2 p_kx1 F_z / (I_y_w u_w)`` (~4500 / u_w 1/s for the BMW 320i, past RK4's
    bound at 1 ms below ~1.6 m/s), bound the substep like ST's block.

    **MB's own constraints and brakes.** After each substep the plant applies what MB's
    right-hand side asks of its state but cannot enforce on the integrator's copy: no negative
    wheel speed (clipped at 0; otherwise a wheel that locked under braking keeps a negative speed
    with derivative 0 and never rolls again), and below 0.1 m/s, where the model moves
    kinematically, yaw rate, lateral speeds and wheel speeds held at the kinematic motion (they
    drive nothing there and would drift, and the model would leave its kinematic branch with a
    hub speed near 0). MB turns its acceleration input into brake and engine torques open loop;
    the plant adds anti-lock brakes and traction control (:meth:`_mb_slip_control`), as the car
    has, so that a wheel on which the torque exceeds the grip does not lock or spin up.
    """

    def __init__(self, model: str, vehicle: str, *, max_step_s: float | None = None):
        if model not in _SHORT:
            raise ValueError(f"unknown CommonRoad plant model {model!r} (known: {', '.join(_SHORT)})")
        if max_step_s is None:
            max_step_s = _DEFAULT_STEP_S[model]
        if isinstance(max_step_s, bool) or not (
            isinstance(max_step_s, (int, float)) and math.isfinite(max_step_s) and max_step_s > 0
        ):
            raise ValueError(f"max_step_s must be a positive number of seconds, got {max_step_s!r}")
        p = vehicle_parameters(vehicle)
        import vehiclemodels.vehicle_dynamics_ks as ks
        import vehiclemodels.vehicle_dynamics_mb as mb
        import vehiclemodels.vehicle_dynamics_st as st

        self.kind, self.vehicle, self.p = model, vehicle, p
        self._rhs = {"ks": ks.vehicle_dynamics_ks, "st": st.vehicle_dynamics_st, "mb": mb.vehicle_dynamics_mb}[model]
        self.max_step_s = float(max_step_s)
        self.model = KinematicBicycle4(KinematicParams(float(p.a), float(p.b)))
        self.name = f"CommonRoad {model.upper()} {vehicle}"
        self._steer = (float(p.steering.min), float(p.steering.max), float(p.steering.v_min), float(p.steering.v_max))

    def __repr__(self) -> str:
        return f"CommonRoadPlant({self.kind!r}, {self.vehicle!r})"

    @property
    def nx(self) -> int:
        """Size of the plant's own state (KS 5, ST 7, MB 29)."""
        return {"ks": 5, "st": 7, "mb": 29}[self.kind]

    def initial_state(self, x0) -> np.ndarray:
        """Plant state for the observed ``[x, y, yaw, v]`` (centre of gravity), wheels straight."""
        x, y, yaw, v = (float(c) for c in np.asarray(x0, float))
        if self.kind == "ks":
            from vehiclemodels.init_ks import init_ks

            lr = float(self.p.b)
            return np.array(init_ks([x - lr * math.cos(yaw), y - lr * math.sin(yaw), 0.0, v, yaw]), float)
        if self.kind == "st":
            from vehiclemodels.init_st import init_st

            return np.array(init_st([x, y, 0.0, v, yaw, 0.0, 0.0]), float)
        from vehiclemodels.init_mb import init_mb

        return np.array(init_mb([x, y, 0.0, v, yaw, 0.0, 0.0], self.p), float)

    def observe(self, xp) -> np.ndarray:
        """Observed ``[x, y, yaw, v]`` of the centre of gravity of plant state(s) ``xp`` (..., nx)."""
        xp = np.asarray(xp, float)
        out = np.empty(xp.shape[:-1] + (4,))
        if self.kind == "ks":
            lr, wb = float(self.p.b), float(self.p.a + self.p.b)
            out[..., 0] = xp[..., 0] + lr * np.cos(xp[..., 4])
            out[..., 1] = xp[..., 1] + lr * np.sin(xp[..., 4])
            out[..., 2] = xp[..., 4]
            out[..., 3] = xp[..., 3] / np.cos(np.arctan(lr / wb * np.tan(xp[..., 2])))
        elif self.kind == "st":
            out[..., :2] = xp[..., :2]
            out[..., 2] = xp[..., 4]
            out[..., 3] = xp[..., 3]
        else:
            out[..., :2] = xp[..., :2]
            out[..., 2] = xp[..., 4]
            # the speed the model moves its centre of gravity with: below |v_x| = 0.1 m/s its pose
            # follows the kinematic model at v_x (v_y is then not coupled to the pose)
            vx = xp[..., 3]
            out[..., 3] = np.where(np.abs(vx) < 0.1, vx, np.hypot(vx, xp[..., 10]))
        return out

    def f(self, xp, u) -> np.ndarray:
        """CommonRoad's right-hand side at plant state ``xp`` for inputs ``u = [steering velocity
        rad/s, acceleration m/s^2]`` (the package function, unmodified; its input limits apply)."""
        try:
            return np.array(self._rhs(list(map(float, xp)), [float(u[0]), float(u[1])], self.p), float)
        except ZeroDivisionError:
            # MB divides by each wheel's hub speed, which it clips at 0 when the wheel would roll
            # backwards: the car slides sideways or spins (above its 0.1 m/s kinematic switch)
            raise PlantModelError(
                f"CommonRoad's {self.kind.upper()} model divided by zero at v_x = {float(xp[3]):.3g} m/s, "
                f"v_y = {float(xp[10]) if len(xp) > 10 else 0.0:.3g} m/s, yaw rate {float(xp[5]):.3g} rad/s, "
                f"steering {float(xp[2]):.3g} rad (a wheel's hub speed is 0: the car slides sideways or "
                "spins, outside what its equations cover)"
            ) from None

    def stiff_radius(self, xp, accel_mps2: float) -> float:
        """Spectral radius [1/s] of the stiff block at plant state ``xp`` and acceleration
        ``accel_mps2``: ST's yaw-rate / slip-angle block, MB's wheel-spin modes (:meth:`_mb_wheel_radius`);
        0 where the model is kinematic (KS, and ST / MB below 0.1 m/s)."""
        v = float(xp[3])
        if self.kind == "ks" or abs(v) < _KINEMATIC_BELOW:
            return 0.0
        if self.kind == "mb":
            return self._mb_wheel_radius(xp)
        p = self.p
        mu, cs = float(p.tire.p_dy1), -float(p.tire.p_ky1) / float(p.tire.p_dy1)
        lf, lr, h, m, iz = float(p.a), float(p.b), float(p.h_s), float(p.m), float(p.I_z)
        wb = lf + lr
        a = float(np.clip(accel_mps2, -p.longitudinal.a_max, p.longitudinal.a_max))
        ff, fr = cs * (_G * lr - a * h), cs * (_G * lf + a * h)  # front / rear load terms
        j = np.array(
            [
                [-mu * m / (v * iz * wb) * (lf**2 * ff + lr**2 * fr), mu * m / (iz * wb) * (lr * fr - lf * ff)],
                [mu / (v**2 * wb) * (fr * lr - ff * lf) - 1.0, -mu / (v * wb) * (fr + ff)],
            ]
        )
        tr, det = j[0, 0] + j[1, 1], j[0, 0] * j[1, 1] - j[0, 1] * j[1, 0]
        disc = tr * tr / 4.0 - det
        if disc >= 0:
            return float(abs(tr / 2.0) + math.sqrt(disc))
        return float(math.sqrt(det))  # complex pair: |lambda| = sqrt(det)

    def _mb_hub_speeds(self, x) -> tuple[float, float, float, float]:
        """MB's wheel-hub speeds (left front, right front, left rear, right rear) [m/s], as its
        right-hand side computes them (before it clips them at 0)."""
        p, d, r, vx, vy = self.p, float(x[2]), float(x[5]), float(x[3]), float(x[10])
        lat = (vy + float(p.a) * r) * math.sin(d)
        return (
            (vx + 0.5 * float(p.T_f) * r) * math.cos(d) + lat,
            (vx - 0.5 * float(p.T_f) * r) * math.cos(d) + lat,
            vx + 0.5 * float(p.T_r) * r,
            vx - 0.5 * float(p.T_r) * r,
        )

    def _mb_wheel_radius(self, x) -> float:
        """Bound [1/s] on the spectral radius of MB's wheel-spin modes at state ``x``.

        A wheel spins as ``I_y_w omega' = -R_w F_x(s) + torque`` with the slip ``s = 1 - R_w
        omega / u_w`` (``u_w`` the hub speed); ``F_x`` is the magic formula, steepest at ``s = 0``
        with slope ``K_x = p_kx1 F_z`` (combined slip only lowers it), so ``|d omega' / d omega| <=
        R_w^2 p_kx1 F_z / (I_y_w u_w)``: ~4500 / u_w 1/s for the BMW 320i (4 s^-1 at 1 m/s per ms),
        the fastest modes of the model below ~20 m/s (its lateral tyre modes, also ~1 / v, are
        some 6 times slower). ``F_z`` per wheel as the model computes it (tyre deflection)."""
        p = self.p
        kzt, rw, tf, tr = float(p.K_zt), float(p.R_w), float(p.T_f), float(p.T_r)
        rf, rr = float(x[13]), float(x[18])
        fz = (
            (float(x[16]) + rw * (math.cos(rf) - 1.0) - 0.5 * tf * math.sin(rf)) * kzt,
            (float(x[16]) + rw * (math.cos(rf) - 1.0) + 0.5 * tf * math.sin(rf)) * kzt,
            (float(x[21]) + rw * (math.cos(rr) - 1.0) - 0.5 * tr * math.sin(rr)) * kzt,
            (float(x[21]) + rw * (math.cos(rr) - 1.0) + 0.5 * tr * math.sin(rr)) * kzt,
        )
        gain = rw * rw * abs(float(p.tire.p_kx1)) / float(p.I_y_w)
        rho = 0.0
        for f_z, u_w in zip(fz, self._mb_hub_speeds(x)):
            if f_z > 0.0:
                rho = max(rho, gain * f_z / max(u_w, _MB_MIN_HUB_SPEED))
        return rho

    def _mb_slip_control(self, x, accel_mps2: float) -> float:
        """The acceleration input given to MB for the command ``accel_mps2`` at state ``x``: the
        command scaled down while a wheel slips beyond the tyre's force peak (anti-lock brakes when
        braking, traction control when driving), as a car's brake / drive system does.

        MB turns its acceleration input into brake torques (split ``T_sb`` front / rear, the same
        on left and right) and engine torques (split ``T_se``) on the wheels, open loop: the
        torque for ``-a_max`` exceeds what a lightly loaded wheel can transmit (inner wheels in a
        turn, the rear axle under braking), which then locks (slip 1), loses its side force and
        spins the car. From the slip ``s = 1 - R_w omega / u_w`` of each wheel (counted on the
        side being used: ``s`` braking, ``-s`` driving) the plant takes ``s_m``, the larger of the
        front axle's smaller slip and the rear wheels' slips (one input for all wheels: "select
        low" on the rear axle, which must not lock or the car spins, "select high" on the front, a
        lightly loaded inner front wheel in a bend does not release the brakes), and scales the
        command by ``clip((s_off - s_m) / (s_off - s_on), 0, 1)``: unchanged up to ``s_on``
        (0.10), no torque from ``s_off`` (0.20). The magic formula's longitudinal force peaks at
        ``s ~ 0.15`` for every parameter set (where ``B_x kappa - E_x (B_x kappa - atan(B_x
        kappa)) = tan(pi / (2 C_x))``, ``B_x = p_kx1 / (C_x p_dx1)`` independent of the load), so
        the wheels work near their peak force and keep most of their side force. Below ``|v_x| =
        0.1`` m/s (the kinematic branch: no slip) the command is passed unchanged."""
        vx = float(x[3])
        if accel_mps2 == 0.0 or abs(vx) < _KINEMATIC_BELOW:
            return accel_mps2
        rw, sign = float(self.p.R_w), (1.0 if accel_mps2 < 0.0 else -1.0)
        slip = [
            sign * (1.0 - rw * float(x[23 + i]) / u_w) if u_w > 0.0 else 0.0
            for i, u_w in enumerate(self._mb_hub_speeds(x))
        ]
        s_m = max(min(slip[0], slip[1]), slip[2], slip[3], 0.0)
        scale = min(max((_MB_SLIP_OFF - s_m) / (_MB_SLIP_OFF - _MB_SLIP_ON), 0.0), 1.0)
        return accel_mps2 * scale

    def _mb_project(self, x) -> np.ndarray:
        """MB's state after a substep, held on the constraints its right-hand side states.

        * "Negative wheel spin forbidden": the right-hand side sets a negative wheel speed to 0
          (and its derivative to 0) on its own copy of the state, which does not reach the
          integrator; without it a wheel that once crossed 0 under braking stays below 0 for good
          (derivative 0), locked even after the brakes are released. The plant clips it at 0.
        * Below ``|v_x| = 0.1`` m/s the model moves kinematically (slip 0 on every tyre, pose
          from the kinematic single track); its yaw rate, lateral speeds and wheel speeds then
          drive nothing and drift (its yaw-rate equation there uses the roll angle in place of
          the slip angle). The plant holds them at the kinematic motion: yaw rate ``v_x tan(delta)
          / L``, lateral speed ``lr`` times it (``lr``: CoG to rear axle; axles with no slip
          angle), the unsprung masses moving with the axles and the wheels rolling at their hub
          speeds. The model leaves its kinematic branch from that consistent state (not from a
          drifted yaw rate that puts a hub speed at 0)."""
        for i in range(23, 27):
            if x[i] < 0.0:
                x[i] = 0.0
        vx = float(x[3])
        if abs(vx) < _KINEMATIC_BELOW:
            p = self.p
            a, b = float(p.a), float(p.b)
            r = vx * math.tan(float(x[2])) / (a + b)
            x[5], x[10] = r, b * r
            x[15], x[20] = (a + b) * r, 0.0  # lateral speeds of the front / rear axles
            rw = float(p.R_w)
            for i, u_w in enumerate(self._mb_hub_speeds(x)):
                x[23 + i] = max(u_w, 0.0) / rw
        return x

    def step(self, xp, u, dt_s: float) -> np.ndarray:
        """Plant state after holding the command ``u = [steering angle rad, acceleration m/s^2]``
        for ``dt_s`` seconds (servo, brakes and substeps as in the class docstring)."""
        x = np.array(xp, float)
        s_min, s_max, sv_min, sv_max = self._steer
        delta_cmd = min(max(float(u[0]), s_min), s_max)
        a_cmd = float(u[1])
        n = max(1, math.ceil(dt_s / self.max_step_s - 1e-9))
        h_max = dt_s / n
        t = 0.0
        while t < dt_s * (1.0 - 1e-12):
            h = min(h_max, dt_s - t)
            rho = self.stiff_radius(x, a_cmd)
            if rho * h > _RK4_STABLE:
                h = _RK4_STABLE / rho
            sv = min(max((delta_cmd - x[2]) / h, sv_min), sv_max)
            a = a_cmd if self.kind != "mb" else self._mb_slip_control(x, a_cmd)
            if a < 0.0:
                a = 0.0 if x[3] <= 0.0 else max(a, -x[3] / h)
            ui = (sv, a)
            k1 = self.f(x, ui)
            k2 = self.f(x + 0.5 * h * k1, ui)
            k3 = self.f(x + 0.5 * h * k2, ui)
            k4 = self.f(x + h * k3, ui)
            x = x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            if self.kind == "mb":
                x = self._mb_project(x)
            t += h
            if not np.all(np.isfinite(x)):
                break
        return x
