"""Markdown report of ``mpcdrive reproduce``: metrics tables, ours-vs-paper, figures.

The report reads finished results (metrics dicts as in ``metrics.json``, docs/interfaces.md, and
figure files already written); it never runs a controller or solver.

Example::

    entries = [ReportEntry("paper-exp1", "Straight line, N = 20", metrics,
                           ["paper-exp1/trajectory.png", "paper-exp1/lateral_deviation.png"])]
    paper = {"paper-exp1": [("max |e_y| [m]", "about 0.5 m", "max_abs_lateral_error_m")]}
    write_reproduce_report(out_dir, entries, paper)      # -> out_dir/report.md
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from urllib.parse import quote

from mpcdrive.io.atomic import atomic_write_text
from mpcdrive.units import rad2deg

__all__ = [
    "PaperFigure",
    "PaperValue",
    "ReportEntry",
    "paper_comparison",
    "render_reproduce_report",
    "run_verdict_text",
    "verdict",
    "write_reproduce_report",
]


@dataclass(frozen=True)
class PaperFigure:
    """The paper's number behind one row of the ours-vs-paper table, for its verdict.

    value : the paper's number in the metric's unit (SI, radians); ``kind`` says what it is:
      ``"about"`` a value read off a figure (ours within :data:`MATCH_TOLERANCE` of it matches;
      lower than that is ``better`` when ``lower_is_better``), ``"at_most"`` a bound the paper's
      curve stays below (ours at most 10 % above it matches), ``"at_least"`` a bound it stays
      above (an obstacle avoided: clearance at least 0), ``"lower_than"`` the paper's claim
      that this run's metric is lower than run ``relative_to``'s (compared with our run of it).
    note : why the paper's figure and ours are not comparable, shown as a footnote where the
      verdict is ``differs``.
    """

    value: float | None = None
    kind: str = "about"
    lower_is_better: bool = True
    relative_to: str | None = None
    note: str = ""

    def __post_init__(self):
        if self.kind not in ("about", "at_most", "at_least", "lower_than"):
            raise ValueError(f"PaperFigure kind must be about, at_most, at_least or lower_than, got {self.kind!r}")
        if (self.kind == "lower_than") != (self.relative_to is not None) or (
            self.kind != "lower_than" and _num(self.value) is None
        ):
            raise ValueError("PaperFigure: about / at_most / at_least need a value, lower_than a relative_to run")


#: one row of the ours-vs-paper table: (quantity name, the paper's value as text,
#: metrics key — dotted for nesting, e.g. ``"solve_time_us.p99"`` — or a function of the metrics
#: [, :class:`PaperFigure`: the paper's number, for the verdict column])
PaperValue = tuple  # (str, str, str | Callable[[Mapping], float | None][, PaperFigure])

#: relative difference within which ours matches a number read off the paper's figures
MATCH_TOLERANCE = 0.10
VERDICT_RULE = (
    "Verdict: *matches* when ours is within 10 % of the paper's number (or, where the paper "
    "gives a bound, at most 10 % beyond it; where it claims a reduction against another run, "
    "lower than our run of that one), *better* when ours is lower than the paper's number by "
    "more than that and lower is better (an error), *differs* otherwise (the footnote says "
    "why), *no number* where the paper states no number to compare with."
)

_DEFAULT_TITLE = "mpcdrive — reproduction of the paper experiments"
_DEFAULT_INTRO = (
    "Closed-loop runs of every experiment of *Safe Driving Using Model Predictive Control For "
    "Autonomous Vehicles*, produced by `mpcdrive reproduce`. Errors are measured on the true "
    "(plant) state against the reference path; angles are reported in degrees, times in "
    "microseconds of controller wall time per step. The numbers come from each run's "
    "`metrics.json`; the figures lie next to this file."
)
_MISSING = "—"


@dataclass(frozen=True)
class ReportEntry:
    """One experiment of the report.

    id : experiment id (``paper-exp1``); description : one or more lines of text;
    metrics : the run's metrics dict (docs/interfaces.md keys, SI units, radians);
    figures : figure paths relative to the report directory (``paper-exp1/trajectory.png``).
    """

    id: str
    description: str
    metrics: Mapping
    figures: list[str] = field(default_factory=list)


def _as_entry(entry) -> ReportEntry:
    if isinstance(entry, ReportEntry):
        return entry
    if isinstance(entry, Mapping):
        unknown = set(entry) - {"id", "description", "metrics", "figures"}
        if unknown:
            raise ValueError(f"report entry has unknown key(s) {sorted(unknown)}")
        return ReportEntry(
            id=str(entry["id"]),
            description=str(entry.get("description", "")),
            metrics=entry.get("metrics") or {},
            figures=[str(f) for f in entry.get("figures", [])],
        )
    # any object with the four attributes
    return ReportEntry(
        id=str(entry.id),
        description=str(getattr(entry, "description", "")),
        metrics=getattr(entry, "metrics", None) or {},
        figures=[str(f) for f in getattr(entry, "figures", [])],
    )


def run_verdict_text(metrics: Mapping) -> tuple[str, str]:
    """(headline, sentence) of a run's verdict, as its metrics hold it (``metrics["verdict"]``;
    judged from the metrics when they have none, :func:`~mpcdrive.sim.run_verdict`): ``UNSAFE``,
    ``FAILED`` or ``passed``, and the verdict's text (``UNSAFE: collided with ...``)."""
    v = metrics.get("verdict")
    if not isinstance(v, Mapping):
        from mpcdrive.sim.verdict import run_verdict

        v = run_verdict(metrics).as_dict()
    return str(v["headline"]), str(v["text"])


def _lookup(metrics: Mapping, key: str):
    """``metrics[key]`` with dotted keys descending into nested dicts; None when absent."""
    value = metrics
    for part in key.split("."):
        if not isinstance(value, Mapping) or part not in value:
            return None
        value = value[part]
    return value


def _num(value) -> float | None:
    if value is None or isinstance(value, bool):
        return None
    try:
        f = float(value)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _fmt(value, digits: int = 4) -> str:
    """Number -> text with ``digits`` significant digits; ints stay ints; missing -> '—'."""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    f = _num(value)
    if f is None:
        return _MISSING
    if f == int(f) and abs(f) < 1e6 and not isinstance(value, float):
        return str(int(f))
    return f"{f:.{digits}g}"


def _fmt_us(value) -> str:
    """Microseconds: whole numbers from 100 us up, one decimal below; missing -> '—'."""
    f = _num(value)
    if f is None:
        return _MISSING
    return f"{f:.0f}" if abs(f) >= 100 else f"{f:.1f}"


def _deg(value) -> float | None:
    f = _num(value)
    return None if f is None else float(rad2deg(f))


def _abs(value) -> float | None:
    f = _num(value)
    return None if f is None else abs(f)


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> list[str]:
    lines = ["| " + " | ".join(_cell(h) for h in header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return lines


def metrics_summary(entries: Sequence[ReportEntry]) -> tuple[list[str], list[list[str]]]:
    """Header and rows (experiment id first, then formatted values) of the summary table;
    shared by the Markdown and HTML reports. Figure-only entries have no row."""
    entries = [e for e in entries if e.metrics]
    has_converged = any("converged_rms_lateral_error_m" in e.metrics for e in entries)
    has_obstacles = any(_num(e.metrics.get("min_obstacle_clearance_m")) is not None for e in entries)
    columns: list[tuple[str, Callable[[Mapping], str]]] = [
        ("steps", lambda m: _fmt(m.get("steps"))),
        ("RMS e_y [m]", lambda m: _fmt(m.get("rms_lateral_error_m"))),
        ("max |e_y| [m]", lambda m: _fmt(m.get("max_abs_lateral_error_m"))),
        ("final |e_y| [m]", lambda m: _fmt(_abs(m.get("final_lateral_error_m")))),
    ]
    if has_converged:
        columns.append(("converged RMS e_y [m]", lambda m: _fmt(m.get("converged_rms_lateral_error_m"))))
    columns += [
        ("max |steer| [deg]", lambda m: _fmt(_deg(m.get("max_abs_steer_rad")))),
        ("max steer rate [deg/s]", lambda m: _fmt(_deg(m.get("max_abs_steer_rate_rad_s")))),
    ]
    if has_obstacles:
        columns += [
            ("min clearance [m]", lambda m: _fmt(m.get("min_obstacle_clearance_m"))),
            ("collisions", lambda m: _fmt(m.get("collisions"))),
        ]
    columns += [
        ("solver failures", lambda m: _fmt(m.get("solver_failures"))),
        ("fallbacks", lambda m: _fmt(m.get("fallbacks"))),
        ("solve p50 [µs]", lambda m: _fmt_us(_lookup(m, "solve_time_us.p50"))),
        ("solve p99 [µs]", lambda m: _fmt_us(_lookup(m, "solve_time_us.p99"))),
    ]
    columns.append(("run verdict", lambda m: run_verdict_text(m)[0]))
    header = ["experiment"] + [c[0] for c in columns]
    rows = [[e.id] + [f(e.metrics) for _, f in columns] for e in entries]
    return header, rows


def _metrics_table(entries: Sequence[ReportEntry]) -> list[str]:
    header, rows = metrics_summary(entries)
    return _table(header, [[f"`{r[0]}`"] + r[1:] for r in rows])


def _ours_value(metrics: Mapping | None, source):
    if metrics is None:
        return None
    if callable(source):
        try:
            return source(metrics)
        except KeyError:  # a metric the run did not record
            return None
    return _lookup(metrics, str(source))


def _ours(metrics: Mapping | None, source) -> str:
    return "not run" if metrics is None else _fmt(_ours_value(metrics, source))


def verdict(ours, figure: PaperFigure | None, reference=None) -> tuple[str, str]:
    """(verdict word, reason) of our value against the paper's ``figure`` (see
    :data:`VERDICT_RULE`); ``reference``: our value of the ``relative_to`` run. The reason is
    the figure's note, or the numbers, where the verdict is ``differs``; else ''."""
    if figure is None:
        return "no number", ""
    x = _num(ours)
    if x is None:
        return "not run", ""
    if figure.kind == "lower_than":
        ref = _num(reference)
        if ref is None:
            return "not run", ""
        if x < ref:
            return "matches", ""
        return "differs", figure.note or f"Ours {_fmt(x)} is not lower than {_fmt(ref)} of {figure.relative_to}."
    v = float(figure.value)
    tol = MATCH_TOLERANCE * abs(v)
    if figure.kind == "at_most":
        if x <= v + tol:
            return "matches", ""
        return "differs", figure.note or f"Ours {_fmt(x)} is {_fmt(x / v, 2)}x the paper's bound {_fmt(v)}."
    if figure.kind == "at_least":
        if x >= v - tol:
            return "matches", ""
        return "differs", figure.note or f"Ours {_fmt(x)} is below the paper's {_fmt(v)}."
    if abs(x - v) <= tol:
        return "matches", ""
    if figure.lower_is_better == (x < v):
        return "better", ""
    return "differs", figure.note or f"Ours {_fmt(x)} against the paper's {_fmt(v)}."


def paper_comparison(
    entries: Sequence[ReportEntry], paper_values: Mapping[str, Sequence[PaperValue]]
) -> tuple[list[str], list[list[str]], list[str]]:
    """Header, rows (experiment id, quantity, paper value, ours, verdict) and footnotes of the
    ours-vs-paper table; ids without an entry read "not run". A row that differs names its
    footnote (``differs [1]``); the same reason is one footnote for every row it explains."""
    by_id = {e.id: e.metrics for e in entries}
    order = [e.id for e in entries if e.id in paper_values]
    order += [i for i in paper_values if i not in by_id]
    rows, notes = [], []
    for exp_id in order:
        for row in paper_values[exp_id]:
            quantity, paper_text, source = row[:3]
            figure = row[3] if len(row) > 3 else None
            metrics = by_id.get(exp_id)
            reference = None
            if figure is not None and figure.relative_to is not None:
                reference = _ours_value(by_id.get(figure.relative_to), source)
            word, reason = verdict(_ours_value(metrics, source), figure, reference)
            if metrics is None:
                word = "not run"
            elif reason:
                if reason not in notes:
                    notes.append(reason)
                word = f"{word} [{notes.index(reason) + 1}]"
            rows.append([exp_id, quantity, paper_text, _ours(metrics, source), word])
    return ["experiment", "quantity", "paper", "ours", "verdict"], rows, notes


def _paper_table(entries: Sequence[ReportEntry], paper_values: Mapping[str, Sequence[PaperValue]]) -> list[str]:
    header, rows, notes = paper_comparison(entries, paper_values)
    lines = _table(header, [[f"`{r[0]}`"] + r[1:] for r in rows])
    if notes:
        lines.append("")
        lines += [f"[{i}] {note}  " for i, note in enumerate(notes, 1)]
    return lines


def _image_link(fig: str) -> str:
    rel = PurePosixPath(str(fig).replace("\\", "/"))
    if rel.is_absolute():
        raise ValueError(f"figure path {fig!r} must be relative to the report directory")
    alt = rel.stem.replace("_", " ")
    return f"![{alt}]({quote(str(rel), safe='/-_.~')})"


def render_reproduce_report(
    entries: Iterable,
    paper_values: Mapping[str, Sequence[PaperValue]] | None = None,
    *,
    title: str = _DEFAULT_TITLE,
    intro: str = _DEFAULT_INTRO,
) -> str:
    """The report as Markdown text (see :func:`write_reproduce_report`)."""
    items = [_as_entry(e) for e in entries]
    ids = [e.id for e in items]
    dupes = sorted({i for i in ids if ids.count(i) > 1})
    if dupes:
        raise ValueError(f"duplicate experiment id(s) in report entries: {dupes}")
    lines = [f"# {title}", "", intro.strip(), "", "## Summary", ""]
    if items:
        lines += _metrics_table(items)
    else:
        lines.append("No experiments were run.")
    if paper_values:
        lines += [
            "",
            "## Ours vs paper",
            "",
            (
                "The paper's values are quoted as text (read from its figures and prose); "
                "ours come from the metrics of the run. " + VERDICT_RULE
            ),
            "",
        ]
        lines += _paper_table(items, paper_values)
    for e in items:
        lines += ["", f"## `{e.id}`", ""]
        if e.metrics:
            lines += [f"**Verdict: {_verdict_sentence(e.metrics)}**", ""]
        if e.description.strip():
            lines += [e.description.strip(), ""]
        for fig in e.figures:
            lines += [_image_link(fig), ""]
        if lines[-1] == "":
            lines.pop()
    return "\n".join(lines) + "\n"


def _verdict_sentence(metrics: Mapping) -> str:
    """``passed: <findings>`` or the verdict's text (``UNSAFE: ...``, ``FAILED: ...``)."""
    headline, text = run_verdict_text(metrics)
    return text if headline != "passed" else f"passed: {text}"


def write_reproduce_report(
    out_dir: str | os.PathLike,
    entries: Iterable,
    paper_values: Mapping[str, Sequence[PaperValue]] | None = None,
    *,
    title: str = _DEFAULT_TITLE,
    intro: str = _DEFAULT_INTRO,
) -> Path:
    """Write ``out_dir/report.md`` atomically and return its path.

    entries : :class:`ReportEntry` objects, dicts with keys ``id``, ``description``, ``metrics``,
        ``figures``, or objects with those attributes; figure paths relative to ``out_dir``.
    paper_values : experiment id -> list of ``(quantity, paper value as text, source)`` where
        ``source`` is a metrics key (dotted for nested, ``"solve_time_us.p99"``) or a callable
        ``metrics -> float | None``.  Ids without an entry are listed as "not run".

    Layout: title, intro, a summary table (one row per experiment: steps, RMS / max / final
    lateral error [m], converged RMS when any run has it, max |steer| [deg], max steering rate
    [deg/s], clearance and collisions when any run has obstacles, solver failures, fallbacks,
    solve time p50 / p99 [µs]), the ours-vs-paper table, then one section per experiment with
    its description and figures as relative image links.
    """
    text = render_reproduce_report(entries, paper_values, title=title, intro=intro)
    return atomic_write_text(Path(out_dir) / "report.md", text)
