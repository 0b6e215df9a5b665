"""Convert states between models with different layouts (model mismatch: a kinematic controller
on a dynamic plant, and back for logging its predictions).

Every model's state starts with the pose ``x [m], y [m], yaw [rad]``; the rest is read by name:
``v`` (speed of the centre of gravity, kinematic models), ``vx``, ``vy`` [m/s] and ``r`` [rad/s]
(dynamic models). Going through the common body-velocity form ``(x, y, yaw, vx, vy, r)``:
``v -> (vx = v, vy = 0, r = 0)`` and ``(vx, vy) -> v = hypot(vx, vy)``; a model without a speed
state (constant-speed kinematic) reports its own speed.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .base import VehicleModel

_KNOWN = {"x", "y", "yaw", "v", "vx", "vy", "r"}


def _check(model: VehicleModel) -> None:
    names = tuple(model.state_names)
    if names[:3] != ("x", "y", "yaw"):
        raise ValueError(f"states must start with x, y, yaw; {type(model).__name__} has {names}")
    unknown = [n for n in names if n not in _KNOWN]
    if unknown:
        raise ValueError(f"cannot convert state(s) {', '.join(unknown)} of {type(model).__name__}")


def _to_body(model: VehicleModel, x: np.ndarray) -> np.ndarray:
    names = tuple(model.state_names)
    out = np.zeros(x.shape[:-1] + (6,))
    out[..., :3] = x[..., :3]
    if "vx" in names:
        out[..., 3] = x[..., names.index("vx")]
    elif "v" in names:
        out[..., 3] = x[..., names.index("v")]
    else:
        out[..., 3] = model.speed(x)
    if "vy" in names:
        out[..., 4] = x[..., names.index("vy")]
    if "r" in names:
        out[..., 5] = x[..., names.index("r")]
    return out


def _from_body(model: VehicleModel, b: np.ndarray) -> np.ndarray:
    names = tuple(model.state_names)
    out = np.zeros(b.shape[:-1] + (len(names),))
    for i, n in enumerate(names):
        if n == "v":
            out[..., i] = np.hypot(b[..., 3], b[..., 4])
        else:
            out[..., i] = b[..., ("x", "y", "yaw", "vx", "vy", "r").index(n)]
    return out


def state_converter(src: VehicleModel, dst: VehicleModel) -> Callable[[np.ndarray], np.ndarray]:
    """A function mapping states ``(..., src.nx)`` of ``src`` to states ``(..., dst.nx)`` of ``dst``."""
    _check(src)
    _check(dst)
    if tuple(src.state_names) == tuple(dst.state_names):
        return lambda x: np.array(x, dtype=float)

    def convert(x):
        return _from_body(dst, _to_body(src, np.asarray(x, float)))

    return convert
