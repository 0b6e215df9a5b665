"""What a sweep varies: ``NAME=DISTRIBUTION`` and ``NAME=VALUE`` settings on a scenario.

``NAME`` is a dotted path into the resolved scenario (the YAML keys; list items by index), e.g.
``initial_state.y_m``, ``vehicle.lr_m``, ``path.points.2.1``, ``obstacles.0.center.0``.
Distributions (numbers only):

* ``uniform(a, b)``, ``normal(mu, sigma)``: the value itself;
* ``offset_uniform(a, b)``, ``offset_normal(mu, sigma)``: the scenario's value plus the sample;
* ``scale_uniform(a, b)``, ``scale_normal(mu, sigma)``: the scenario's value times the sample;
* ``choice(v1, v2, ...)``: one of the listed values, equally likely.

A field holding an integer (the horizon, say) receives the sample rounded to the nearest integer.
Every problem is a :class:`SweepError` whose message is one line naming the option and the issue.
"""

from __future__ import annotations

import copy
import math
import re
from dataclasses import dataclass

import numpy as np
import yaml

__all__ = ["DISTRIBUTIONS", "Distribution", "Setting", "SweepError", "Variation", "parse_set", "parse_vary"]


class SweepError(ValueError):
    """Bad sweep input; ``str()`` is one line naming the option, field and problem."""


#: distribution name -> number of parameters (None = one or more)
DISTRIBUTIONS: dict[str, int | None] = {
    "uniform": 2,
    "normal": 2,
    "offset_uniform": 2,
    "offset_normal": 2,
    "scale_uniform": 2,
    "scale_normal": 2,
    "choice": None,
}
_CALL = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*\((.*)\)\s*$")
_NAME = re.compile(r"^[A-Za-z0-9_]+(\.[A-Za-z0-9_]+)*$")
#: keys a sweep sets itself
_RESERVED = {"seed": "the sweep gives every run its own seed (use --seed)", "id": "the sweep names every run"}


@dataclass(frozen=True)
class Distribution:
    """A named distribution with its parameters (see the module docstring)."""

    kind: str
    params: tuple[float, ...]

    @property
    def relative(self) -> bool:
        """Whether the sample is combined with the scenario's own value."""
        return self.kind.startswith(("offset_", "scale_"))

    def nominal(self, base):
        """A representative value (the distribution's centre) used to check the option up front."""
        a = self.params
        if self.kind == "choice":
            return a[0]
        centre = 0.5 * (a[0] + a[1]) if self.kind.endswith("uniform") else a[0]
        return self._combine(centre, base)

    def sample(self, rng: np.random.Generator, base):
        a = self.params
        if self.kind == "choice":
            return a[int(rng.integers(len(a)))]
        x = float(rng.uniform(a[0], a[1])) if self.kind.endswith("uniform") else float(rng.normal(a[0], a[1]))
        return self._combine(x, base)

    def _combine(self, x: float, base):
        if self.kind.startswith("offset_"):
            return base + x
        if self.kind.startswith("scale_"):
            return base * x
        return x

    def __str__(self) -> str:
        return f"{self.kind}({', '.join(f'{p:g}' for p in self.params)})"


def _parse_distribution(option: str, name: str, text: str) -> Distribution:
    m = _CALL.match(text)
    if not m:
        raise SweepError(
            f"{option} {name}: expected a distribution like uniform(-0.5, 0.5), got {text!r} "
            f"(known: {', '.join(DISTRIBUTIONS)})"
        )
    kind, body = m.group(1), m.group(2)
    if kind not in DISTRIBUTIONS:
        raise SweepError(f"{option} {name}: unknown distribution {kind!r} (known: {', '.join(DISTRIBUTIONS)})")
    parts = [p.strip() for p in body.split(",")] if body.strip() else []
    params = []
    for p in parts:
        try:
            v = float(p)
        except ValueError:
            raise SweepError(f"{option} {name}: {kind} parameter {p!r} is not a number") from None
        if not math.isfinite(v):
            raise SweepError(f"{option} {name}: {kind} parameter {p!r} is not finite")
        params.append(v)
    need = DISTRIBUTIONS[kind]
    if need is None and not params:
        raise SweepError(f"{option} {name}: {kind} needs at least one value")
    if need is not None and len(params) != need:
        raise SweepError(f"{option} {name}: {kind} takes {need} parameters, got {len(params)}")
    if kind.endswith("uniform") and params[0] > params[1]:
        raise SweepError(f"{option} {name}: {kind} lower bound {params[0]:g} exceeds upper bound {params[1]:g}")
    if kind.endswith("normal") and params[1] < 0:
        raise SweepError(f"{option} {name}: {kind} standard deviation {params[1]:g} is negative")
    return Distribution(kind, tuple(params))


def _split_assignment(option: str, text: str) -> tuple[str, str]:
    if "=" not in text:
        example = {"--vary": "NAME=DISTRIBUTION (e.g. initial_state.y_m=uniform(-0.5, 0.5))"}.get(
            option, "NAME=VALUE (e.g. road.lane_width_m=0.8)"
        )
        raise SweepError(f"{option} {text!r}: expected {example}")
    name, value = text.split("=", 1)
    name = name.strip()
    if not _NAME.match(name):
        raise SweepError(
            f"{option} {name!r}: NAME must be a dotted path of keys and list indices, "
            "e.g. initial_state.y_m or path.points.0.1"
        )
    top = name.split(".")[0]
    if top in _RESERVED:
        raise SweepError(f"{option} {name}: cannot be set, {_RESERVED[top]}")
    return name, value.strip()


def _keys(name: str) -> tuple[str | int, ...]:
    return tuple(int(p) if p.isdigit() else p for p in name.split("."))


def _describe(node) -> str:
    if isinstance(node, dict):
        return f"a mapping with keys {', '.join(map(str, node)) or '(none)'}"
    if isinstance(node, list):
        return f"a list of {len(node)} items"
    return f"the value {node!r}"


def get_value(data: dict, keys: tuple, option: str, name: str):
    """The value at ``keys`` in nested ``data`` (None for a key that is absent or unset)."""
    node = data
    for i, k in enumerate(keys):
        where = ".".join(map(str, keys[:i])) or "the scenario"
        if isinstance(node, dict):
            if isinstance(k, int) or k not in node:
                raise SweepError(f"{option} {name}: {where} has no key {k!r} (it is {_describe(node)})")
            node = node[k]
        elif isinstance(node, list):
            if not isinstance(k, int) or not (0 <= k < len(node)):
                raise SweepError(f"{option} {name}: {where} has no item {k!r} (it is {_describe(node)})")
            node = node[k]
        elif node is None:
            return None  # an unset section (road: null): setting it creates it
        else:
            raise SweepError(f"{option} {name}: {where} is {_describe(node)}, not a mapping or list")
    return node


def set_value(data: dict, keys: tuple, value) -> None:
    """Set ``keys`` in nested ``data`` to ``value``, creating unset (None) sections as mappings."""
    node = data
    for k, nxt in zip(keys[:-1], keys[1:]):
        child = node[k]
        if child is None:
            child = node[k] = [] if isinstance(nxt, int) else {}
        elif isinstance(child, tuple):
            child = node[k] = list(child)
        node = child
    node[keys[-1]] = value


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


@dataclass(frozen=True)
class Variation:
    """One ``--vary NAME=DISTRIBUTION``."""

    name: str
    keys: tuple
    dist: Distribution
    integer: bool = False

    def value(self, rng: np.random.Generator, data: dict):
        v = self.dist.sample(rng, get_value(data, self.keys, "--vary", self.name))
        return int(round(v)) if self.integer else float(v)

    def __str__(self) -> str:
        return f"{self.name}={self.dist}"


@dataclass(frozen=True)
class Setting:
    """One ``--set NAME=VALUE`` (VALUE read as YAML: numbers, booleans, lists, ...)."""

    name: str
    keys: tuple
    value: object

    def __str__(self) -> str:
        return f"{self.name}={yaml.safe_dump(self.value, default_flow_style=True).strip().removesuffix('...').strip()}"


def parse_set(text: str, data: dict) -> Setting:
    """Parse ``NAME=VALUE`` against the scenario ``data`` (a resolved scenario as plain data)."""
    name, raw = _split_assignment("--set", text)
    keys = _keys(name)
    get_value(data, keys, "--set", name)  # the path must exist (or lie under an unset section)
    from ..scenarios.loader import read_yaml

    try:
        value = read_yaml(raw) if raw else None
    except (yaml.YAMLError, ValueError):
        raise SweepError(f"--set {name}: value {raw!r} is not valid YAML") from None
    return Setting(name, keys, value)


def parse_vary(text: str, data: dict) -> Variation:
    """Parse ``NAME=DISTRIBUTION`` against the scenario ``data`` (a resolved scenario as plain data)."""
    name, raw = _split_assignment("--vary", text)
    keys = _keys(name)
    dist = _parse_distribution("--vary", name, raw)
    base = get_value(data, keys, "--vary", name)
    if base is not None and not _is_number(base):
        hint = f"; vary one of its numbers, e.g. {name}.0" if isinstance(base, list) else ""
        raise SweepError(f"--vary {name}: holds {_describe(base)}, not a number{hint}")
    if base is None and dist.relative:
        raise SweepError(
            f"--vary {name}: is not set in this scenario, so {dist.kind} has nothing to "
            "offset or scale; use uniform/normal, or --set it first"
        )
    return Variation(name, keys, dist, integer=isinstance(base, int))


def apply(data: dict, settings, values: dict) -> dict:
    """A deep copy of ``data`` with ``settings`` and ``values`` ({Variation: value}) applied."""
    out = copy.deepcopy(data)
    for s in settings:
        set_value(out, s.keys, copy.deepcopy(s.value))
    for var, v in values.items():
        set_value(out, var.keys, v)
    return out
