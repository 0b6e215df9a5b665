"""``trajectory.csv`` and JSON output of a closed-loop run (reads results, never solves).

``trajectory.csv`` (docs/interfaces.md) has one row per control step and the columns

    t, x, y, yaw, v, steer, accel, s, e_y, e_psi, solve_time_us, status, fallback

followed by any further model states (``SimResult.state_names`` other than x, y, yaw, v).
Units: t [s], x, y, s, e_y [m], yaw, steer, e_psi [rad], v [m/s], accel [m/s^2],
solve_time_us [us]; ``status`` is the solver status word (``ok`` when solved) and ``fallback``
the fallback used ("" when none).  Floats are written with ``repr`` precision, so they read back
bit-exactly; NaN and infinities are written as ``nan`` / ``inf``.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from mpcdrive.io.atomic import atomic_write_text
from mpcdrive.types import SimResult

__all__ = [
    "TRAJECTORY_COLUMNS",
    "read_trajectory_csv",
    "to_jsonable",
    "trajectory_columns",
    "write_json",
    "write_trajectory_csv",
]

#: the fixed leading columns of ``trajectory.csv``, in order
TRAJECTORY_COLUMNS: tuple[str, ...] = (
    "t",
    "x",
    "y",
    "yaw",
    "v",
    "steer",
    "accel",
    "s",
    "e_y",
    "e_psi",
    "solve_time_us",
    "status",
    "fallback",
)
#: columns holding text; all others are floats
_TEXT_COLUMNS = frozenset({"status", "fallback"})
#: model states already covered by the fixed columns
_STATES_IN_FIXED = frozenset({"x", "y", "yaw", "v"})


def _extra_state_columns(result: SimResult) -> list[tuple[str, int]]:
    """(column name, state index) for model states not among x, y, yaw, v.

    A state whose name clashes with a fixed column (say a ``steer`` state of a model with
    steering dynamics) is written as ``state_<name>``.
    """
    extra = []
    for i, name in enumerate(result.state_names):
        if name in _STATES_IN_FIXED:
            continue
        col = f"state_{name}" if name in TRAJECTORY_COLUMNS else name
        extra.append((col, i))
    return extra


def trajectory_columns(result: SimResult) -> list[str]:
    """Header of ``trajectory.csv`` for ``result``: the fixed columns, then extra states."""
    return list(TRAJECTORY_COLUMNS) + [c for c, _ in _extra_state_columns(result)]


def _fmt(value: float) -> str:
    return repr(float(value))


def write_trajectory_csv(result: SimResult, path: str | os.PathLike) -> Path:
    """Write ``result`` as ``trajectory.csv`` at ``path`` atomically; return the path.

    One row per control step (``result.steps`` rows), columns as in the module docstring.
    """
    K = result.steps
    extra = _extra_state_columns(result)
    numeric = [
        result.t_s,
        result.x[:, 0],
        result.x[:, 1],
        result.yaw_rad,
        result.v_mps,
        result.steer_rad,
        result.accel_mps2,
        result.s_m,
        result.e_y_m,
        result.e_psi_rad,
        np.asarray(result.solve_time_s, dtype=float) * 1e6,
    ]
    numeric = [np.asarray(a, dtype=float).reshape(-1) for a in numeric]
    extra_cols = [np.asarray(result.x[:, i], dtype=float) for _, i in extra]
    for name, arr in zip(TRAJECTORY_COLUMNS, numeric):
        if arr.shape[0] != K:
            raise ValueError(f"SimResult field for column {name!r} has {arr.shape[0]} rows, expected {K} (len(t_s))")
    if len(result.status) != K or len(result.fallback) != K:
        raise ValueError(
            f"SimResult.status / fallback must have {K} entries, got {len(result.status)} / {len(result.fallback)}"
        )

    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(trajectory_columns(result))
    for k in range(K):
        row = [_fmt(a[k]) for a in numeric]
        row.append(str(result.status[k]))
        row.append(str(result.fallback[k]))
        row.extend(_fmt(a[k]) for a in extra_cols)
        writer.writerow(row)
    return atomic_write_text(path, buf.getvalue())


def read_trajectory_csv(path: str | os.PathLike) -> dict[str, np.ndarray | list[str]]:
    """Read a ``trajectory.csv``: column name -> float array (K,), or list of K strings for the
    text columns ``status`` and ``fallback``.  Column order is kept (dicts are ordered)."""
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.reader(fh)
        try:
            header = next(reader)
        except StopIteration:
            raise ValueError(f"{path}: empty file, expected a trajectory.csv header") from None
        rows = [r for r in reader if r]
    for n, r in enumerate(rows, start=2):
        if len(r) != len(header):
            raise ValueError(f"{path}: line {n} has {len(r)} fields, header has {len(header)}")
    cols = list(zip(*rows)) if rows else [()] * len(header)
    out: dict[str, np.ndarray | list[str]] = {}
    for name, values in zip(header, cols):
        if name in _TEXT_COLUMNS:
            out[name] = list(values)
        else:
            try:
                out[name] = np.array([float(v) for v in values], dtype=float)
            except ValueError as exc:
                raise ValueError(f"{path}: column {name!r} is not numeric ({exc})") from None
    return out


def to_jsonable(obj):
    """Convert ``obj`` to plain JSON types.

    numpy scalars and arrays become Python numbers and lists, tuples/sets lists, mappings (a
    :class:`~mpcdrive.sim.Metrics` too) and dataclasses dicts, paths strings, dict keys strings;
    NaN and +-inf become ``None`` (JSON null). Anything else raises ``TypeError`` naming the type.
    """
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        f = float(obj)
        return f if math.isfinite(f) else None
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):  # complex, str_, ... -> python scalar
        return to_jsonable(obj.item())
    if isinstance(obj, Mapping):  # before dataclasses: a Metrics is both, its items the JSON view
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, (set, frozenset)):
        return [to_jsonable(v) for v in sorted(obj, key=repr)]
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return to_jsonable({f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)})
    raise TypeError(f"cannot write object of type {type(obj).__name__} to JSON")


def write_json(path: str | os.PathLike, obj) -> Path:
    """Write ``obj`` as JSON at ``path`` atomically (indent 2, sorted keys, trailing newline).

    numpy types are converted and NaN/inf written as ``null`` (see :func:`to_jsonable`).
    Returns the path written.
    """
    text = json.dumps(to_jsonable(obj), indent=2, sort_keys=True, allow_nan=False)
    return atomic_write_text(path, text + "\n")
