"""Interactive HTML report: a replay of each drive, its metrics and its figures, in one file.

The page is self-contained: the replay data is embedded as JSON, the figures as base64 PNG, and
the viewer is plain JavaScript drawing on a canvas (no external script, style sheet or font), so
it opens offline in any browser. The viewer and the style sheet are package data
(``assets/replay.js``, ``assets/report.css``), copied into every page as they are. Like the Markdown report it reads finished results and never
runs a controller or solver.

The replay shows, over time: the reference path, the road edges (``road_profile``),
the driven trajectory, the vehicle footprint (a ``Footprint`` rectangle turned by the yaw), the
predicted horizon of each step (``SimResult.X_pred``) and, when ``result.meta["obstacles"]``
lists them, the obstacles. Obstacle shapes (metres, radians)::

    {"type": "circle", "center": [x, y], "radius_m": r}
    {"type": "polygon", "points": [[x, y], ...]}
    {"type": "rectangle", "center": [x, y], "length_m": l, "width_m": w, "yaw_rad": yaw}

A shape moves when its position is given per time: ``center`` of shape (T, 2) or ``points`` of
shape (T, P, 2) (``yaw_rad`` may be (T,) too), at times ``t_s`` (T,) [s] or, without ``t_s``, one
entry per control step. Positions are interpolated linearly to the replay's frames and held
outside ``t_s``. Unknown shape types are listed on the page as not drawn, never dropped
silently; a malformed shape of a known type raises ValueError naming the field.

Example::

    write_run_html(out_dir, result, metrics, ["trajectory.png"], footprint)  # out_dir/report.html
"""

from __future__ import annotations

import base64
import html
import json
import math
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cache
from importlib import resources
from pathlib import Path

import numpy as np

from mpcdrive.io.atomic import atomic_write_text
from mpcdrive.report.markdown import (
    _DEFAULT_INTRO,
    _DEFAULT_TITLE,
    VERDICT_RULE,
    PaperValue,
    ReportEntry,
    _as_entry,
    _fmt,
    _fmt_us,
    _num,
    metrics_summary,
    paper_comparison,
    run_verdict_text,
)
from mpcdrive.scene.geometry import road_edges
from mpcdrive.scene.footprint import Footprint
from mpcdrive.types import STATUS_INACCURATE, STATUS_OK, SimResult

__all__ = ["HtmlRun", "replay_data", "render_html_report", "write_run_html", "write_reproduce_html"]

#: most replay frames kept per run (longer runs are subsampled evenly; the last step is kept)
MAX_FRAMES = 2000
#: most points kept of each predicted horizon
MAX_HORIZON_POINTS = 41
#: most points kept of the reference path polyline
MAX_PATH_POINTS = 3000


@dataclass(frozen=True)
class HtmlRun:
    """One experiment of an HTML report.

    id, description : as in :class:`ReportEntry`; metrics : the run's metrics dict;
    figures : PNG files, absolute or relative to the report directory, embedded in the page;
    result : the run's log (None: no replay, e.g. a comparison figure); footprint : the
    vehicle body drawn in the replay.
    """

    id: str
    description: str
    metrics: Mapping
    figures: list[str | os.PathLike] = field(default_factory=list)
    result: SimResult | None = None
    footprint: Footprint = Footprint()


# --------------------------------------------------------------------------- replay data
def _decimals(extent_m: float) -> int:
    """Decimals that keep positions to about 1e-5 of the scene's extent (0..7)."""
    if not math.isfinite(extent_m) or extent_m <= 0:
        return 4
    return int(min(7, max(0, math.ceil(5.0 - math.log10(extent_m)))))


def _round(a, decimals: int) -> list:
    """Array -> nested lists of rounded floats; non-finite values become None (JSON null)."""
    a = np.round(np.asarray(a, dtype=float), decimals)
    if np.all(np.isfinite(a)):
        return a.tolist()
    out = a.astype(object)
    out[~np.isfinite(a)] = None
    return out.tolist()


def _subsample(n: int, most: int) -> np.ndarray:
    """At most ``most`` indices of range(n), evenly spread, first and last kept."""
    if n <= most:
        return np.arange(n)
    return np.unique(np.round(np.linspace(0, n - 1, most)).astype(int))


def _interp_rows(t_frames: np.ndarray, t_src: np.ndarray, values: np.ndarray) -> np.ndarray:
    """values (T, ...) at times t_src (T,) -> (F, ...) at t_frames, linear, held at the ends."""
    flat = values.reshape(values.shape[0], -1)
    out = np.column_stack([np.interp(t_frames, t_src, flat[:, j]) for j in range(flat.shape[1])])
    return out.reshape((len(t_frames),) + values.shape[1:])


def _obstacle_times(shape: Mapping, i: int, n: int, t_steps: np.ndarray) -> np.ndarray:
    if "t_s" in shape:
        t = np.asarray(shape["t_s"], dtype=float)
        if t.shape != (n,) or not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0):
            raise ValueError(f"obstacles[{i}].t_s: need {n} finite non-decreasing times [s], got shape {t.shape}")
        return t
    if n != len(t_steps):
        raise ValueError(f"obstacles[{i}]: {n} positions over time but the run has {len(t_steps)} steps; give t_s")
    return t_steps


def _xy_array(value, i: int, key: str, *, per_time_ndim: int) -> np.ndarray:
    """An array of positions; (..., 2) with ndim per_time_ndim - 1 (static) or per_time_ndim."""
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"obstacles[{i}].{key}: not an array of numbers") from None
    if a.ndim not in (per_time_ndim - 1, per_time_ndim) or a.shape[-1] != 2:
        raise ValueError(
            f"obstacles[{i}].{key}: expected shape {'(2,)' if per_time_ndim == 2 else '(P, 2)'}"
            f" or one per time, got {a.shape}"
        )
    if not np.all(np.isfinite(a)):
        raise ValueError(f"obstacles[{i}].{key}: not finite")
    return a


def _positive(shape: Mapping, i: int, key: str) -> float:
    try:
        v = float(shape[key])
    except KeyError:
        raise ValueError(f"obstacles[{i}].{key}: missing") from None
    except (TypeError, ValueError):
        raise ValueError(f"obstacles[{i}].{key}: not a number") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"obstacles[{i}].{key}: must be a positive number [m], got {v}")
    return v


def _obstacles(raw, t_frames: np.ndarray, t_steps: np.ndarray, dec: int) -> tuple[list, list[str]]:
    """Obstacle shapes of ``meta["obstacles"]`` as replay records (positions per frame when
    they move), and the names of shape types that are not drawn."""
    if raw is None:
        return [], []
    if isinstance(raw, Mapping) or not isinstance(raw, Iterable):
        raise ValueError("obstacles: expected a list of shapes")
    shapes, skipped = [], []
    for i, sh in enumerate(raw):
        if hasattr(sh, "to_dict") and callable(sh.to_dict):
            sh = sh.to_dict()
        if not isinstance(sh, Mapping):
            raise ValueError(f"obstacles[{i}]: expected a mapping with a 'type', got {type(sh).__name__}")
        kind = str(sh.get("type", ""))
        label = str(sh.get("label", sh.get("id", "")))
        if kind == "circle":
            c = _xy_array(sh.get("center"), i, "center", per_time_ndim=2)
            rec = {"type": "circle", "r": round(_positive(sh, i, "radius_m"), dec)}
            if c.ndim == 2:
                c = _interp_rows(t_frames, _obstacle_times(sh, i, len(c), t_steps), c)
            rec["c"] = _round(c, dec)
        elif kind == "polygon":
            p = _xy_array(sh.get("points"), i, "points", per_time_ndim=3)
            if p.shape[-2] < 3:
                raise ValueError(f"obstacles[{i}].points: a polygon needs at least 3 points")
            if p.ndim == 3:
                p = _interp_rows(t_frames, _obstacle_times(sh, i, len(p), t_steps), p)
            rec = {"type": "polygon", "p": _round(p, dec)}
        elif kind == "rectangle":
            c = _xy_array(sh.get("center"), i, "center", per_time_ndim=2)
            yaw = np.asarray(sh.get("yaw_rad", 0.0), dtype=float)
            if yaw.ndim > 1 or not np.all(np.isfinite(yaw)):
                raise ValueError(f"obstacles[{i}].yaw_rad: a finite angle or one per time")
            ln, wd = _positive(sh, i, "length_m"), _positive(sh, i, "width_m")
            if c.ndim == 2 or yaw.ndim == 1:
                n = len(c) if c.ndim == 2 else len(yaw)
                t = _obstacle_times(sh, i, n, t_steps)
                c = np.broadcast_to(c, (n, 2)) if c.ndim == 1 else c
                yaw = np.broadcast_to(yaw, (n,)) if yaw.ndim == 0 else np.unwrap(yaw)
                if len(c) != n or len(yaw) != n:
                    raise ValueError(f"obstacles[{i}]: center and yaw_rad differ in length")
                c = _interp_rows(t_frames, t, c)
                yaw = np.interp(t_frames, t, yaw)
            # as a polygon: four corners, per frame when it moves
            hl, hw = 0.5 * ln, 0.5 * wd
            body = np.array([[hl, hw], [hl, -hw], [-hl, -hw], [-hl, hw]])
            cy, sy = np.cos(yaw)[..., None], np.sin(yaw)[..., None]
            px = c[..., None, 0] + cy * body[:, 0] - sy * body[:, 1]
            py = c[..., None, 1] + sy * body[:, 0] + cy * body[:, 1]
            rec = {"type": "polygon", "p": _round(np.stack([px, py], axis=-1), dec)}
        else:
            skipped.append(kind or "(no type)")
            continue
        if label:
            rec["label"] = label
        shapes.append(rec)
    return shapes, skipped


def _encode_horizon(hz: np.ndarray, xy: np.ndarray, dec: int) -> list[list[int]]:
    """Predicted horizons (F, n, 2) [m] as integers in units of 10**-dec m, per frame
    ``[dx0, dy0, dx1, dy1, ...]``: the first point relative to the frame's (rounded) position,
    each next one relative to the previous point (differences of rounded coordinates, so the
    decoded points carry no accumulated error). A frame with non-finite points is empty."""
    scale = 10.0**dec
    out = []
    for k in range(hz.shape[0]):
        h = hz[k]
        if not h.shape[0] or not (np.all(np.isfinite(h)) and np.all(np.isfinite(xy[k]))):
            out.append([])
            continue
        q = np.round(h * scale).astype(np.int64)
        base = np.round(np.round(xy[k], dec) * scale).astype(np.int64)
        d = np.diff(np.vstack([base, q]), axis=0)
        out.append(d.reshape(-1).tolist())
    return out


def replay_data(
    result: SimResult, footprint: Footprint = Footprint(), *, run_id: str = "", max_frames: int = MAX_FRAMES
) -> dict:
    """The JSON-ready replay of one run: frames subsampled to at most ``max_frames``, positions
    rounded to about 1e-5 of the scene's size, angles to 1e-5 rad.

    Keys: ``id``, ``dt`` [s], ``path`` / ``left`` / ``right`` (polylines [[x, y], ...] [m];
    boundaries null without a lane), ``closed``, ``footprint`` (length, width, centre offset [m]),
    ``frames`` (per frame: ``k`` step index, ``t`` [s], ``x``, ``y`` [m], ``yaw`` [rad], ``v``
    [m/s], ``steer`` [rad], ``accel`` [m/s^2], ``ey`` [m], ``epsi`` [rad], ``st`` status code),
    ``statuses`` (status words of the codes), ``horizon`` (per frame the predicted [x, y]
    points), ``obstacles``, ``skipped_obstacles``, ``max_steer`` [rad] or null.
    """
    if max_frames < 2:
        raise ValueError(f"max_frames must be >= 2, got {max_frames}")
    K = result.steps
    if K < 1:
        raise ValueError("result has no steps to replay")
    xy = np.asarray(result.xy, dtype=float)
    path = np.asarray(result.path_xy, dtype=float).reshape(-1, 2)
    path = path[_subsample(len(path), MAX_PATH_POINTS)]
    left = right = None
    if result.road_profile is not None and len(path) >= 2:
        left, right = road_edges(path, result.road_profile)
    idx = _subsample(K, max_frames)
    t_frames = np.asarray(result.t_s, dtype=float)[idx]
    X = np.asarray(result.X_pred, dtype=float) if result.X_pred is not None else None
    if X is not None and X.ndim == 3 and X.shape[0] == K and X.shape[2] >= 2 and X.shape[1]:
        hz = X[idx][:, _subsample(X.shape[1], MAX_HORIZON_POINTS), :2]
    else:
        hz = np.zeros((len(idx), 0, 2))
    pieces = [xy, path, hz.reshape(-1, 2)] + ([left, right] if left is not None else [])
    extent_pts = np.vstack([p for p in pieces if len(p)])
    extent_pts = extent_pts[np.all(np.isfinite(extent_pts), axis=1)]
    extent = float(np.max(np.ptp(extent_pts, axis=0))) if len(extent_pts) else 1.0
    dec = _decimals(max(extent, footprint.length_m))
    t_steps = np.asarray(result.t_s, dtype=float)
    obstacles, skipped = _obstacles(result.meta.get("obstacles"), t_frames, t_steps, dec)
    statuses = sorted(set(result.status))
    code = {s: j for j, s in enumerate(statuses)}
    closed = bool(len(path) > 2 and np.hypot(*(path[0] - path[-1])) < 1e-6 * max(extent, 1e-9))
    max_steer = _num(result.meta.get("max_steer_rad"))
    return {
        "id": run_id or str(result.meta.get("id", "")),
        "dt": float(result.dt_s),
        "steps": K,
        "decimals": dec,
        "path": _round(path, dec),
        "closed": closed,
        "left": None if left is None else _round(left, dec),
        "right": None if right is None else _round(right, dec),
        "footprint": {
            "length": float(footprint.length_m),
            "width": float(footprint.width_m),
            "offset": float(footprint.center_offset_m),
        },
        "frames": {
            "k": idx.tolist(),
            "t": _round(t_frames, 6),
            "x": _round(xy[idx, 0], dec),
            "y": _round(xy[idx, 1], dec),
            "yaw": _round(np.asarray(result.yaw_rad, float)[idx], 5),
            "v": _round(np.asarray(result.v_mps, float)[idx], 4),
            "steer": _round(np.asarray(result.steer_rad, float)[idx], 5),
            "accel": _round(np.asarray(result.accel_mps2, float)[idx], 4),
            "ey": _round(np.asarray(result.e_y_m, float)[idx], dec + 1),
            "epsi": _round(np.asarray(result.e_psi_rad, float)[idx], 5),
            "st": [code[result.status[k]] for k in idx],
        },
        "statuses": statuses,
        "ok_statuses": [s for s in statuses if s in (STATUS_OK, STATUS_INACCURATE)],
        "horizon": _encode_horizon(hz, xy[idx], dec),
        "obstacles": obstacles,
        "skipped_obstacles": skipped,
        "max_steer": max_steer,
        "lanelets": _lanelets(result.meta.get("lanelets"), extent_pts, dec),
    }


def _lanelets(polygons, view_pts: np.ndarray, dec: int) -> list:
    """The road's lanelet polygons (``meta["lanelets"]``: lists of (x, y) [m]) within 30 m of
    what the replay shows, rounded."""
    if not polygons or not len(view_pts):
        return []
    lo, hi = view_pts.min(axis=0) - 30.0, view_pts.max(axis=0) + 30.0
    out = []
    for poly in polygons:
        p = np.asarray(poly, float).reshape(-1, 2)
        if len(p) >= 3 and np.all(p.max(axis=0) >= lo) and np.all(p.min(axis=0) <= hi):
            out.append(_round(p, dec))
    return out


# --------------------------------------------------------------------------- page
def _e(text) -> str:
    return html.escape(str(text), quote=True)


def _image_tag(path: Path, alt: str) -> str:
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return (
        f'<figure><img alt="{_e(alt)}" src="data:image/png;base64,{data}"><figcaption>{_e(alt)}</figcaption></figure>'
    )


def _figure_file(fig, base_dir: Path | None) -> Path:
    p = Path(fig)
    if not p.is_absolute():
        if base_dir is None:
            raise ValueError(f"figure path {str(fig)!r} is relative but no report directory was given")
        p = base_dir / p
    if p.suffix.lower() != ".png":
        raise ValueError(f"figure {str(fig)!r}: only PNG files can be embedded")
    if not p.is_file():
        raise ValueError(f"figure {str(fig)!r}: no such file")
    return p


def _event_text(ev: Mapping) -> str:
    """A collision event (``metrics["collision_events"]``) in words."""
    who = f"obstacle {ev.get('obstacle')}" + (f" ({ev['name']})" if ev.get("name") else "")
    return f"{who} at t = {_fmt(ev.get('t_s'))} s, {_fmt(ev.get('depth_m'))} m deep"


def _value_text(key: str, value) -> str:
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (list, tuple)) and all(isinstance(v, Mapping) for v in value):
        return "none" if not value else _e("; ".join(_event_text(v) for v in value))
    if isinstance(value, Mapping) and "t_s" in value:
        return _e(_event_text(value))
    f = _num(value)
    if f is None:
        return _e(value)
    if key.endswith("_us") or key.startswith("solve_time_us."):
        return f"{_fmt_us(f)} µs"
    if key.endswith("_rad_s"):
        return f"{_fmt(value)} rad/s ({math.degrees(f):.4g}°/s)"
    if key.endswith("_rad"):
        return f"{_fmt(value)} rad ({math.degrees(f):.4g}°)"
    for suffix, unit in (("_m", "m"), ("_s", "s"), ("_mps", "m/s"), ("_mps2", "m/s²")):
        if key.endswith(suffix):
            return f"{_fmt(value)} {unit}"
    return _fmt(value)


def _flatten(metrics: Mapping, prefix: str = "") -> list[tuple[str, object]]:
    rows = []
    for k, v in metrics.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping):
            rows += _flatten(v, key + ".")
        else:
            rows.append((key, v))
    return rows


def _verdict_paragraph(metrics: Mapping) -> str:
    """The run's verdict as a sentence (``UNSAFE: collided with ...``), marked by its headline."""
    if not metrics:
        return ""
    headline, text = run_verdict_text(metrics)
    body = text[len(headline) + 2 :] if text.startswith(headline + ": ") else text
    return (
        f'<p class="verdict {_e(headline.lower())}">Verdict: <strong>{_e(headline)}</strong>'
        f"{': ' if body else ''}{_e(body)}</p>"
    )


def _metrics_table(metrics: Mapping) -> str:
    if not metrics:
        return ""
    shown = {k: v for k, v in metrics.items() if k != "verdict"}  # the verdict is the sentence above
    rows = "".join(f"<tr><th><code>{_e(k)}</code></th><td>{_value_text(k, v)}</td></tr>" for k, v in _flatten(shown))
    return f'<table class="metrics"><tbody>{rows}</tbody></table>'


def _inline_markup(text: str) -> str:
    """Escaped text with Markdown's ``*emphasis*`` and ```code``` turned into HTML."""
    out = _e(text)
    out = re.sub(r"`([^`]+)`", r"<code>\1</code>", out)
    return re.sub(r"\*([^*]+)\*", r"<em>\1</em>", out)


def _table(header: Sequence[str], rows: Iterable[Sequence[str]], *, id_links: bool = False, text: bool = False) -> str:
    head = "".join(f"<th>{_e(h)}</th>" for h in header)
    body = []
    for r in rows:
        first = (
            f'<a href="#" class="pick" data-run="{_e(r[0])}"><code>{_e(r[0])}</code></a>'
            if id_links
            else f"<code>{_e(r[0])}</code>"
        )
        body.append("<tr><td>" + first + "</td>" + "".join(f"<td>{_e(c)}</td>" for c in r[1:]) + "</tr>")
    cls = "text" if text else "summary"
    return f'<table class="{cls}"><thead><tr>{head}</tr></thead><tbody>{"".join(body)}</tbody></table>'


def _json_script(element_id: str, data) -> str:
    text = json.dumps(data, separators=(",", ":"), allow_nan=False, ensure_ascii=True)
    text = text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")
    return f'<script type="application/json" id="{element_id}">{text}</script>'


def render_html_report(
    runs: Sequence[HtmlRun],
    *,
    title: str,
    intro: str = "",
    base_dir: str | os.PathLike | None = None,
    paper_values: Mapping[str, Sequence[PaperValue]] | None = None,
    summary: bool | None = None,
    max_frames: int = MAX_FRAMES,
) -> str:
    """The page as text. ``runs`` with a ``result`` get a replay (an experiment selector when
    there are several); ``summary`` adds the table of every run's metrics (default: when there
    are several runs); ``paper_values`` adds the ours-vs-paper table; figures are read from
    ``base_dir`` when relative."""
    runs = list(runs)
    ids = [r.id for r in runs]
    dupes = sorted({i for i in ids if ids.count(i) > 1})
    if dupes:
        raise ValueError(f"duplicate experiment id(s) in report runs: {dupes}")
    base = None if base_dir is None else Path(base_dir)
    replays = [
        replay_data(r.result, r.footprint, run_id=r.id, max_frames=max_frames) for r in runs if r.result is not None
    ]
    entries = [ReportEntry(r.id, r.description, r.metrics, []) for r in runs]
    parts = [f"<h1>{_e(title)}</h1>"]
    if len(runs) == 1:  # one run: its verdict before anything else
        parts.append(_verdict_paragraph(runs[0].metrics))
    if intro.strip():
        parts.append(f'<p class="intro">{_inline_markup(intro.strip())}</p>')
    if summary is None:
        summary = len(runs) > 1
    if summary and any(e.metrics for e in entries):
        header, rows = metrics_summary(entries)
        parts.append("<h2>Summary</h2>" + _table(header, rows, id_links=bool(replays)))
    if replays:
        picker = ""
        if len(replays) > 1:
            opts = "".join(f'<option value="{_e(r["id"])}">{_e(r["id"])}</option>' for r in replays)
            picker = f'<label>experiment <select id="experiment">{opts}</select></label>'
        parts.append(_REPLAY_PANEL.replace("{picker}", picker))
    sections, extras = [], []
    for r in runs:
        body = [f'<h2 id="run-{_e(r.id)}"><code>{_e(r.id)}</code></h2>']
        if len(runs) > 1:
            body.append(_verdict_paragraph(r.metrics))
        if r.description.strip():
            body.append(f"<p>{_e(r.description.strip())}</p>")
        body.append(_metrics_table(r.metrics))
        figs = [_image_tag(_figure_file(f, base), Path(f).stem.replace("_", " ")) for f in r.figures]
        if figs:
            body.append('<div class="figures">' + "".join(figs) + "</div>")
        cls = "run" if r.result is not None else "extra"
        (sections if r.result is not None else extras).append(
            f'<section class="{cls}" data-run="{_e(r.id)}">{"".join(body)}</section>'
        )
    parts += sections
    if paper_values:
        header, rows, notes = paper_comparison(entries, paper_values)
        foot = "".join(f'<p class="note">[{i}] {_e(n)}</p>' for i, n in enumerate(notes, 1))
        parts.append(
            "<h2>Ours vs paper</h2><p>The paper's values are quoted as text (read from "
            "its figures and prose); ours come from the metrics of the run. "
            f"{_inline_markup(VERDICT_RULE)}</p>" + _table(header, rows, text=True) + foot
        )
    parts += extras
    return (
        _PAGE_HEAD.replace("{style}", _asset("report.css")).replace("{title}", _e(title))
        + "\n".join(parts)
        + _json_script("replay-data", replays)
        + "<script>\n"
        + _asset("replay.js")
        + "</script>\n"
        + "</body></html>\n"
    )


def write_run_html(
    out_dir: str | os.PathLike,
    result: SimResult,
    metrics: Mapping,
    figures: Sequence[str | os.PathLike] = (),
    footprint: Footprint = Footprint(),
    *,
    run_id: str | None = None,
    description: str | None = None,
    max_frames: int = MAX_FRAMES,
) -> Path:
    """Write ``out_dir/report.html`` for one run (replay, metrics, embedded figures)."""
    rid = run_id if run_id is not None else str(result.meta.get("id", "run"))
    desc = description if description is not None else str(result.meta.get("description", ""))
    run = HtmlRun(rid, desc, metrics, list(figures), result, footprint)
    text = render_html_report([run], title=f"mpcdrive run — {rid}", base_dir=out_dir, max_frames=max_frames)
    return atomic_write_text(Path(out_dir) / "report.html", text)


def write_reproduce_html(
    out_dir: str | os.PathLike,
    runs: Iterable,
    paper_values: Mapping[str, Sequence[PaperValue]] | None = None,
    *,
    title: str = _DEFAULT_TITLE,
    intro: str = _DEFAULT_INTRO,
    max_frames: int = MAX_FRAMES,
) -> Path:
    """Write ``out_dir/report.html`` with every experiment: summary and ours-vs-paper tables, a
    replay with an experiment selector, and one section per experiment (metrics, figures).

    runs : :class:`HtmlRun` objects, or report entries (:class:`ReportEntry`, dicts) without a
    replay; figure paths relative to ``out_dir``.
    """
    items = []
    for r in runs:
        if isinstance(r, HtmlRun):
            items.append(r)
        else:
            e = _as_entry(r)
            items.append(HtmlRun(e.id, e.description, e.metrics, list(e.figures)))
    text = render_html_report(
        items,
        title=title,
        intro=intro,
        base_dir=out_dir,
        paper_values=paper_values,
        summary=True,
        max_frames=max_frames,
    )
    return atomic_write_text(Path(out_dir) / "report.html", text)


# --------------------------------------------------------------------------- template
@cache
def _asset(name: str) -> str:
    """A file of the page's assets (package data in ``mpcdrive/report/assets``: the style sheet
    ``report.css`` and the replay viewer ``replay.js``) as text, embedded in every page."""
    return (resources.files("mpcdrive.report") / "assets" / name).read_text(encoding="utf-8")


_PAGE_HEAD = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<link rel="icon" href="data:,">
<title>{title}</title>
<style>
{style}</style></head><body>
"""

_REPLAY_PANEL = """<div id="replay">
<div id="controls">{picker}
<button id="play" type="button">Play</button>
<input id="time-slider" type="range" min="0" max="0" value="0" step="1" aria-label="time">
<span id="frame-label"></span>
<label>speed <select id="speed">
<option value="0.1">0.1×</option><option value="0.25">0.25×</option><option value="0.5">0.5×</option>
<option value="1" selected>1×</option><option value="2">2×</option><option value="5">5×</option>
<option value="10">10×</option><option value="20">20×</option></select></label>
<label><input id="follow" type="checkbox"> follow</label>
<label><input id="show-horizon" type="checkbox" checked> horizon</label>
<button id="reset-view" type="button">fit view</button>
</div>
<canvas id="view" aria-label="replay of the drive"></canvas>
<div id="legend"><span><i style="background:#1f77b4"></i>reference path</span>
<span><i style="background:#555"></i>lane boundary</span><span><i style="background:#d62728"></i>driven</span>
<span><i style="background:#2ca02c"></i>predicted horizon</span><span><i style="background:#9467bd"></i>obstacle</span>
<span><i style="background:#ff7f0e"></i>vehicle</span></div>
<div id="hud"></div><div id="skipped" class="note"></div>
<canvas id="series" aria-label="lateral error and steering over time"></canvas>
<div class="note">Mouse wheel zooms, drag pans, space plays or pauses, arrow keys step; click the lower plot to seek.</div>
</div>
"""
