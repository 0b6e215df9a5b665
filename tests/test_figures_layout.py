"""Figures that do not mislead: long roads readable, moving obstacles shown when they were
closest, distinct colours, titles inside the figure. Structure, never pixels."""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest
from matplotlib.colors import to_rgba
from matplotlib.patches import Polygon as MplPolygon

from mpcdrive.plots import figures, laps
from mpcdrive.plots.common import RUN_COLORS, REF_COLOR, closest_approach, obstacle_outlines, polyline_coordinates
from mpcdrive.types import STATUS_OK, SimResult


def _run(length_m=230.0, lane=2.0, k=200, obstacles=None, name="long-road", e_y=None):
    """A car driving along y = 0 from x = 0 to ``length_m`` (a straight path) in ``k`` steps."""
    dt = 0.05
    t = np.arange(k) * dt
    x = np.linspace(0.0, length_m * 0.9, k)
    e = 0.3 * np.sin(x / length_m * 6.0) if e_y is None else e_y
    X = np.column_stack([x, e, np.zeros(k)])
    z = np.zeros(k)
    meta = {"id": name, "max_steer_rad": 0.5}
    if obstacles is not None:
        meta["obstacles"] = obstacles
    return SimResult(
        t_s=t,
        x=X,
        u=z[:, None],
        x_final=X[-1].copy(),
        s_m=x.copy(),
        e_y_m=e,
        e_psi_rad=z,
        yaw_rad=z,
        v_mps=np.full(k, 5.0),
        steer_rad=z,
        accel_mps2=z,
        X_pred=None,
        refs=None,
        status=(STATUS_OK,) * k,
        fallback=("",) * k,
        solve_time_s=np.full(k, 1e-4),
        path_xy=np.column_stack([np.linspace(0.0, length_m, 400), np.zeros(400)]),
        dt_s=dt,
        state_names=("x", "y", "yaw"),
        input_names=("steer",),
        road_profile=np.array([[0.0, lane / 2, -lane / 2], [length_m, lane / 2, -lane / 2]]),
        lane_excess_m=np.zeros(k),
        goal_reached=None,
        meta=meta,
    )


def _crossing(k=200):
    """A circle crossing the road at x = 10 m from y = -3 m to y = +3 m; the car passes at 2 m/s."""
    t = np.arange(k) * 0.05
    centres = np.column_stack([np.full(k, 10.0), -3.0 + 6.0 * t / t[-1]])
    return {"name": "walker", "moving": True, "type": "circle", "radius_m": 0.3, "center": centres.tolist()}


def _filled(ax):
    return [p for p in ax.patches if isinstance(p, MplPolygon)]


def test_a_long_road_gets_a_panel_in_path_coordinates():
    res = _run()
    fig = figures._make_trajectory(res)
    ax_map, ax_s = fig.get_axes()
    assert ax_map.get_xlabel() == "x [m]" and ax_map.get_aspect() == 1.0  # the map stays true to scale
    assert ax_s.get_xlabel() == "distance along the path s [m]" and ax_s.get_ylabel() == "lateral offset e_y [m]"
    driven = {ln.get_label(): ln for ln in ax_s.get_lines()}["driven trajectory"]
    np.testing.assert_allclose(driven.get_xdata(), res.s_m)
    np.testing.assert_allclose(driven.get_ydata(), res.e_y_m)
    # the lateral axis shows the lane (+-1 m) readably: a few metres, not the road's 230 m
    lo, hi = ax_s.get_ylim()
    assert 2.0 <= hi - lo <= 10.0 and lo < -1.0 and hi > 1.0
    # the overview swaps its map for the path-coordinate view
    over = figures._make_overview(res).get_axes()[0]
    assert over.get_xlabel() == "distance along the path s [m]"
    # a compact road keeps the single map
    short = _run(length_m=8.0, lane=2.0)
    assert len(figures._make_trajectory(short).get_axes()) == 1
    assert figures._make_overview(short).get_axes()[0].get_xlabel() == "x [m]"


def test_a_long_road_speed_map_gets_speed_along_the_path():
    axes = laps._make_speed_map(_run()).get_axes()
    assert [a.get_xlabel() for a in axes if a.get_lines()][-1] == "distance along the path s [m]"


def test_moving_obstacle_is_drawn_once_at_its_closest_approach_with_the_time():
    res = _run(length_m=20.0, lane=4.0, obstacles=[_crossing()], e_y=np.zeros(200))  # 20 m x 4 m: one map
    fig = figures._make_trajectory(res)
    (ax,) = fig.get_axes()
    outlines = obstacle_outlines(res.meta["obstacles"][0])
    k = closest_approach(outlines, res.xy)
    # where the car is nearest: at x = 10 m while the walker is nearest y = 0
    assert abs(res.xy[k, 0] - 10.0) < 0.6
    (patch,) = _filled(ax)  # one outline, not a row of untimed snapshots
    v = patch.get_xy()
    np.testing.assert_allclose([v.min(axis=0), v.max(axis=0)], [outlines[k].min(axis=0), outlines[k].max(axis=0)])
    texts = [t.get_text() for t in ax.texts if t.get_text()]  # (the arrow of its track has none)
    assert texts == [f"t = {res.t_s[k]:.1f} s"]
    vehicle = {ln.get_label(): ln for ln in ax.get_lines()}["vehicle at that time"]
    np.testing.assert_allclose(vehicle.get_xydata()[0], res.xy[k])
    # the same in path coordinates on a long road
    long = _run(obstacles=[_crossing()], e_y=np.zeros(200))
    ax_map, ax_s = figures._make_trajectory(long).get_axes()
    k = closest_approach(obstacle_outlines(long.meta["obstacles"][0]), long.xy)
    assert [t.get_text() for t in ax_s.texts if t.get_text()] == [f"t = {long.t_s[k]:.1f} s"]
    assert len(_filled(ax_map)) == 1 and not [t for t in ax_map.texts if t.get_text()]  # the strip: no label


def test_polyline_coordinates():
    path = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])
    se = polyline_coordinates(path, np.array([[5.0, 1.0], [11.0, 5.0], [9.0, 7.0]]))
    np.testing.assert_allclose(se, [[5.0, 1.0], [15.0, -1.0], [17.0, 1.0]])


def test_reference_and_runs_never_share_a_colour():
    runs = {f"formulation {i}": _run(length_m=8.0, name=f"r{i}") for i in range(4)}
    ax = figures._make_trajectory_overlay(runs).get_axes()[0]
    by_label = {ln.get_label(): to_rgba(ln.get_color()) for ln in ax.get_lines()}
    colours = [by_label[name] for name in runs]
    assert by_label["reference path"] not in colours
    assert len(set(colours)) == len(colours)
    assert to_rgba(REF_COLOR) not in {to_rgba(c) for c in RUN_COLORS}
    # the single-run figure: reference blue, driven red
    one = {
        ln.get_label(): to_rgba(ln.get_color())
        for ln in figures._make_trajectory(runs["formulation 0"]).get_axes()[0].get_lines()
    }
    assert one["reference path"] != one["driven trajectory"]


LONG_NAME = "USA_US101-3_1_T-1_with_a_very_long_scenario_identifier_that_goes_on_and_on"


@pytest.mark.parametrize(
    "make",
    [
        lambda r: figures._make_overview(r),
        lambda r: figures._make_trajectory(r),
        lambda r: figures._make_steering(r),
        lambda r: figures._make_lateral_deviation(r),
        lambda r: laps._make_speed_map(r),
        lambda r: laps._make_lateral_acceleration(r),
    ],
    ids=["overview", "trajectory", "steering", "lateral", "speed_map", "lateral_acceleration"],
)
@pytest.mark.parametrize("length_m", [8.0, 230.0])
def test_titles_are_inside_the_figure(make, length_m):
    fig = make(_run(length_m=length_m, name=LONG_NAME))
    fig.canvas.draw()
    box = fig.bbox
    titles = [ax.title for ax in fig.get_axes() if ax.get_title()]
    if fig._suptitle is not None:
        titles.append(fig._suptitle)
    assert titles
    renderer = fig.canvas.get_renderer()
    for t in titles:
        ext = t.get_window_extent(renderer)
        assert box.x0 - 0.5 <= ext.x0 and ext.x1 <= box.x1 + 0.5, t.get_text()
        assert box.y0 - 0.5 <= ext.y0 and ext.y1 <= box.y1 + 0.5, t.get_text()
        assert (
            LONG_NAME.replace("_", "") in t.get_text().replace("\n", "").replace("_", "").replace(" ", "")
            or "Acceleration" in t.get_text()
            or "Speed along" in t.get_text()
        )


def _imports(module) -> set[str]:
    tree = ast.parse(Path(module.__file__).read_text())
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            names.add(node.module or "")
        elif isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
    return names


def test_no_import_cycle_between_figures_and_laps():
    assert "mpcdrive.plots.figures" not in _imports(laps)
    assert "mpcdrive.plots.laps" in _imports(figures)  # one direction only, both on plots.common
    assert "mpcdrive.plots.common" in _imports(laps) & _imports(figures)


def test_closest_approach_of_a_static_outline_is_its_nearest_step():
    ring = obstacle_outlines({"type": "circle", "center": [3.0, 1.0], "radius_m": 0.5})
    xy = np.column_stack([np.linspace(0, 6, 61), np.zeros(61)])
    assert closest_approach(ring * 61, xy) == 30
    assert math.isclose(xy[30, 0], 3.0)
