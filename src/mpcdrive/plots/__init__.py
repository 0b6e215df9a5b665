"""Figures of closed-loop runs (matplotlib, Agg canvas, no pyplot); read results, never solve."""

from mpcdrive.plots.figures import (
    plot_clearance,
    plot_cost_map,
    plot_heading_deviation,
    plot_lateral_deviation,
    plot_overview,
    plot_speed,
    plot_steering,
    plot_steering_comparison,
    plot_trajectory,
    plot_trajectory_overlay,
    speed_varies,
    write_run_figures,
)
from mpcdrive.plots.laps import plot_lateral_acceleration, plot_speed_map, plot_tracking_comparison

__all__ = [
    "plot_clearance",
    "plot_cost_map",
    "plot_heading_deviation",
    "plot_lateral_acceleration",
    "plot_speed_map",
    "plot_tracking_comparison",
    "plot_lateral_deviation",
    "plot_overview",
    "plot_speed",
    "plot_steering",
    "plot_steering_comparison",
    "plot_trajectory",
    "plot_trajectory_overlay",
    "speed_varies",
    "write_run_figures",
]
