"""Pictures of a CommonRoad run as CommonRoad draws scenarios: commonroad-io's own renderer
(:class:`commonroad.visualization.mp_renderer.MPRenderer`) for the lanelet network, the
obstacles at chosen times and the planning problem, with the driven trajectory and the car on
top; and the lanelet polygons handed to the HTML replay."""

from __future__ import annotations

from pathlib import Path

import numpy as np

FIGURE = "commonroad_scene.png"


def lanelet_polygons(scenario) -> list[list[tuple[float, float]]]:
    """Every lanelet of the scenario as a closed outline (left bound, then the right one back) [m]."""
    out = []
    for ll in scenario.lanelet_network.lanelets:
        ring = np.vstack([ll.left_vertices, ll.right_vertices[::-1]])
        out.append([(float(x), float(y)) for x, y in ring])
    return out


def _car_outline(x: float, y: float, yaw: float, length: float, width: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    corners = np.array(
        [
            [length / 2, width / 2],
            [length / 2, -width / 2],
            [-length / 2, -width / 2],
            [-length / 2, width / 2],
            [length / 2, width / 2],
        ]
    )
    return np.column_stack([x + c * corners[:, 0] - s * corners[:, 1], y + s * corners[:, 0] + c * corners[:, 1]])


def write_scene_figure(imp, result, out_dir: Path, last_step: int | None = None) -> Path:
    """``commonroad_scene.png``: three panels (start, middle, end of the checked drive), each the
    scenario drawn by MPRenderer at that time step with the planning problem, the driven
    trajectory (red) and the car (orange)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from commonroad.visualization.draw_params import MPDrawParams
    from commonroad.visualization.mp_renderer import MPRenderer

    n = len(result.t_s) if last_step is None else last_step + 1
    xy = np.asarray(result.x[:n, :2], float)
    steps = sorted({0, n // 2, n - 1})
    v = imp.spec.vehicle
    pad = 25.0
    lo, hi = xy.min(axis=0) - pad, xy.max(axis=0) + pad
    span = hi - lo
    wide = span[0] >= 1.5 * span[1]  # panels stacked for a wide view, side by side otherwise
    aspect = float(span[1] / span[0])  # height / width of one panel
    fig, axes = (
        plt.subplots(len(steps), 1, figsize=(10, len(steps) * min(max(10 * aspect, 2.0), 6.0) + 0.8))
        if wide
        else plt.subplots(1, len(steps), figsize=(len(steps) * min(max(5 / aspect, 2.5), 5.0), 5.8))
    )
    axes = np.atleast_1d(axes)
    dt = imp.spec.dt_s
    for ax, k in zip(axes, steps):
        ts = int(round(result.t_s[k] / dt))
        params = MPDrawParams()
        params.time_begin = ts
        params.time_end = ts
        # commonroad-io 2024.3's traffic-sign / light artists cannot be measured with this
        # matplotlib (their bounding box raises), so none are drawn and the layout is set by hand
        params.traffic_sign.draw_traffic_signs = False
        params.lanelet_network.traffic_sign.draw_traffic_signs = False
        params.traffic_light.draw_traffic_lights = False
        params.lanelet_network.traffic_light.draw_traffic_lights = False
        rnd = MPRenderer(draw_params=params, ax=ax, plot_limits=[lo[0], hi[0], lo[1], hi[1]])
        imp.scenario.draw(rnd)
        imp.planning_problem.draw(rnd)
        rnd.render()
        ax.plot(xy[:, 0], xy[:, 1], color="#d62728", lw=1.0, alpha=0.3, zorder=40)
        ax.plot(xy[: k + 1, 0], xy[: k + 1, 1], color="#d62728", lw=1.8, zorder=40, label="driven")
        car = _car_outline(*result.x[k, :3], v.length_m, v.width_m)
        ax.fill(car[:, 0], car[:, 1], color="#ff7f0e", alpha=0.9, zorder=41, label="ego")
        ax.set_title(f"t = {result.t_s[k]:.1f} s (step {ts})", fontsize=9)
    axes[0].legend(loc="upper right", fontsize=8)
    fig.suptitle(f"{imp.scenario.scenario_id}: lanelets, obstacles and goal as CommonRoad draws them", fontsize=10)
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.05, top=0.92, hspace=0.3, wspace=0.2)
    path = Path(out_dir) / FIGURE
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
