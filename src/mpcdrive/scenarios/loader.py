"""Load and validate scenario files; built-in scenarios ship as YAML in ``builtin/``."""

from __future__ import annotations

import re
import warnings
from importlib import resources
from pathlib import Path

import yaml
from pydantic import ValidationError

from .schema import ScenarioSpec


class ScenarioError(ValueError):
    """Bad scenario input; ``str()`` is one line naming the file, field and problem."""

    def __init__(self, source: str, field: str, problem: str):
        self.source, self.field, self.problem = source, field, problem
        super().__init__(f"{source}: {field}: {problem}" if field else f"{source}: {problem}")


def _builtin_dir():
    return resources.files(__package__) / "builtin"


def builtin_ids() -> list[str]:
    """Ids of the built-in scenarios, sorted."""
    return sorted(p.name[:-5] for p in _builtin_dir().iterdir() if p.name.endswith(".yaml"))


class _DuplicateKey(Exception):
    def __init__(self, key, line: int):
        self.key, self.line = key, line


class _StrictLoader(yaml.SafeLoader):
    """Safe YAML loader that refuses a key given twice in one mapping (PyYAML keeps the last) and
    reads ``1e-5`` as a number, as YAML 1.2 does (PyYAML's YAML 1.1 wants ``1.0e-5``)."""

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                dup = key in seen
            except TypeError:  # unhashable key: let PyYAML report it
                dup = False
            if dup:
                raise _DuplicateKey(key, key_node.start_mark.line + 1)
            try:
                seen.add(key)
            except TypeError:
                pass
        return super().construct_mapping(node, deep=deep)


_StrictLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def read_yaml(text: str):
    """Parse YAML text as scenario files are parsed (``1e-5`` is a number; duplicate keys raise
    ``ValueError``)."""
    try:
        return yaml.load(text, Loader=_StrictLoader)
    except _DuplicateKey as e:
        raise ValueError(f"line {e.line}: duplicate key {e.key!r}") from None


def _parse(text: str, source: str) -> ScenarioSpec:
    try:
        data = yaml.load(text, Loader=_StrictLoader)
    except _DuplicateKey as e:
        raise ScenarioError(source, f"line {e.line}", f"duplicate key {e.key!r} (each key may appear once)") from None
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark is not None else "YAML"
        raise ScenarioError(source, where, f"not valid YAML ({getattr(e, 'problem', None) or e})") from None
    return validate_scenario_data(data, source)


def validate_scenario_data(data, source: str) -> ScenarioSpec:
    """Validate a scenario given as plain data (a dict as read from YAML); ``source`` names it in
    the one-line :class:`ScenarioError` raised for bad input."""
    if not isinstance(data, dict):
        raise ScenarioError(source, "", "a scenario file must be a YAML mapping of keys to values")
    try:
        spec = ScenarioSpec.model_validate(data)
    except ValidationError as e:
        err = e.errors()[0]
        loc = ".".join(
            str(p) for p in err["loc"] if not (isinstance(p, str) and p in ("straight", "circle", "waypoints", "csv"))
        )
        msg = err["msg"].removeprefix("Value error, ")
        if err["type"] == "extra_forbidden":
            msg = "unknown key"
        elif err["type"] == "missing":
            msg = "required key missing"
        more = f" (and {len(e.errors()) - 1} more problem(s))" if len(e.errors()) > 1 else ""
        raise ScenarioError(source, loc or "(top level)", msg + more) from None
    return reject_initial_overlap(spec, source)


def reject_initial_overlap(spec: ScenarioSpec, source: str) -> ScenarioSpec:
    """``spec``, or :class:`ScenarioError` naming ``obstacles.<i>`` when an obstacle overlaps the
    car's footprint at the start (:func:`~mpcdrive.scenarios.build.initial_overlap`)."""
    from .build import initial_overlap

    overlap = initial_overlap(spec)
    if overlap is not None:
        raise ScenarioError(source, *overlap)
    return spec


def warn_suspicious(spec: ScenarioSpec, source: str) -> ScenarioSpec:
    """Warn (:class:`~mpcdrive.types.ScenarioWarning`, one ``source: field: problem`` message
    each) about every legal but suspicious value of ``spec`` (see
    :func:`~mpcdrive.scenarios.build.scenario_warnings`); returns ``spec``. The checks that need
    the built path run here too: a path that doubles back is a :class:`ScenarioError`
    (:func:`~mpcdrive.scenarios.build.path_doubles_back`), one that turns tighter than the car
    can a warning."""
    from ..types import ScenarioWarning
    from .build import build_path, build_road, load_track, path_doubles_back, scenario_warnings, warn_if_path_too_curved

    for field, problem in scenario_warnings(spec):
        warnings.warn(str(ScenarioError(source, field, problem)), ScenarioWarning, stacklevel=2)
    try:
        track = load_track(spec.path) if spec.path.type == "csv" else None
        path = track.path if track is not None else build_path(spec.path)
        road = build_road(spec.road, path, track)
    except (ValueError, OSError):
        return spec  # build_experiment reports it
    doubled = path_doubles_back(spec, path, road)
    if doubled is not None:
        raise ScenarioError(source, *doubled)
    warn_if_path_too_curved(spec, path, source)
    return spec


def _resolve_track_file(spec: ScenarioSpec, source: str, base_dir: Path | None) -> ScenarioSpec:
    """A CSV path's ``file``: a packaged track name stays as it is; a path is made absolute
    (relative to the scenario file's folder) and must exist."""
    if spec.path.type != "csv":
        return spec
    from .tracks import packaged_track_names

    f = spec.path.file
    if f in packaged_track_names():
        return spec
    p = Path(f)
    if not p.is_absolute():
        if base_dir is None:
            raise ScenarioError(
                source, "path.file", f"no packaged track {f!r} (packaged: {', '.join(packaged_track_names())})"
            )
        p = (base_dir / p).resolve()
    if not p.is_file():
        raise ScenarioError(
            source, "path.file", f"track file not found: {p} (packaged tracks: {', '.join(packaged_track_names())})"
        )
    return spec.model_copy(update={"path": spec.path.model_copy(update={"file": str(p)})})


def load_scenario(name_or_path: str | Path) -> ScenarioSpec:
    """A built-in scenario by id, or a YAML scenario file by path.

    A CSV track ``path.file`` is a packaged track name or a path relative to the scenario file;
    the returned spec holds it as an absolute path. Raises :class:`ScenarioError` (one-line
    message: file, field, problem) on bad input (also an obstacle overlapping the car at the
    start); warns with :class:`~mpcdrive.types.ScenarioWarning` about suspicious values
    (:func:`warn_suspicious`).
    """
    name = str(name_or_path)
    if name in builtin_ids():
        path = _builtin_dir() / f"{name}.yaml"
        source = f"builtin:{name}"
        return warn_suspicious(
            _resolve_track_file(_parse(path.read_text(encoding="utf-8"), source), source, None), source
        )
    p = Path(name)
    if p.suffix.lower() not in (".yaml", ".yml"):
        if not p.exists():
            raise ScenarioError(
                name, "", f"no built-in scenario or file of this name (built-ins: {', '.join(builtin_ids())})"
            )
        raise ScenarioError(name, "", "unsupported file type (expected .yaml or .yml)")
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ScenarioError(name, "", "file not found") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ScenarioError(name, "", f"cannot read file ({e})") from None
    return warn_suspicious(_resolve_track_file(_parse(text, name), name, p.resolve().parent), name)


def dump_scenario(spec: ScenarioSpec) -> str:
    """The fully resolved scenario (all defaults filled in) as YAML text, saying what ran:
    ``controller.solver`` (the reference's QP solver) only where it solves the QP -- on the
    ``osqp`` backend, or ``projected_gradient`` on either -- not next to ``backend: fast``, whose
    condensed solver it is not. Loading the text gives ``spec`` back."""
    data = spec.model_dump(mode="json")
    c = data.get("controller")
    if c is not None and c["backend"] == "fast" and c["solver"] == "osqp":
        del c["solver"]
    return yaml.safe_dump(data, sort_keys=False)
