"""The paper's experiments: which built-in scenarios ``reproduce`` runs and what the paper shows.

Paper values are read off the paper's figures and text (Section VI and Appendix A); they are
quoted as text, next to our measured figures, in the reproduce report.
"""

from __future__ import annotations

PAPER_EXPERIMENTS: tuple[str, ...] = (
    "paper-exp1",
    "paper-exp2",
    "paper-exp3",
    "paper-exp4",
    "paper-disturbance-v1",
    "paper-disturbance-v4",
    "paper-smoothing",
    "paper-exp5-hard",
    "paper-exp5-potential",
    "paper-exp5-gaussian",
    "paper-exp5-corridor",
)

#: obstacle scenarios beyond the paper, run with every formulation by ``compare-avoidance``
AVOIDANCE_SCENARIOS: tuple[str, ...] = (
    "paper-exp5-hard",
    "obstacle-slalom",
    "obstacle-overtake",
    "obstacle-crossing",
    "obstacle-blocked",
)
FORMULATIONS: tuple[str, ...] = ("hard", "corridor", "potential", "gaussian")

#: per formulation, the avoidance settings used by ``compare-avoidance`` (the paper-exp5 tuning)
FORMULATION_TUNING: dict[str, dict] = {
    "hard": {"formulation": "hard"},
    "corridor": {"formulation": "corridor"},
    "potential": {"formulation": "potential", "weight": 1.0, "epsilon_m2": 0.05},
    "gaussian": {"formulation": "gaussian", "weight": 3.0, "sigma_m": [0.4, 0.4]},
}

#: per experiment: (quantity, what the paper shows, metrics key of ours)
PAPER_VALUES: dict[str, list[tuple[str, str, str]]] = {
    "paper-exp1": [
        ("final |lateral error| [m]", "converges slowly to the line within 1000 iterations (Fig. 17)", "final_lateral_error_m"),
        ("max |steering| [rad]", "saturates at the 60 deg bound, 1.047 (Fig. 18)", "max_abs_steer_rad"),
    ],
    "paper-exp2": [
        ("final |lateral error| [m]", "converges, better than N = 20 (Figs. 7, 15)", "final_lateral_error_m"),
        ("max |steering| [rad]", "saturates at the 60 deg bound, 1.047 (Fig. 16)", "max_abs_steer_rad"),
    ],
    "paper-exp3": [
        ("converged max |lateral error| [m]", "below 0.008 (Fig. 19, 'x10^-3' axis)", "converged_max_abs_lateral_error_m"),
        ("max |steering| [rad]", "up to about 50 deg, 0.87 (Fig. 20)", "max_abs_steer_rad"),
    ],
    "paper-exp4": [
        ("converged max |lateral error| [m]", "below 0.012 (Fig. 22)", "converged_max_abs_lateral_error_m"),
    ],
    "paper-disturbance-v1": [
        ("max |lateral error| [m]", "up to 0.04, visible deviation (Figs. 11, 26)", "max_abs_lateral_error_m"),
    ],
    "paper-disturbance-v4": [
        ("max |lateral error| [m]", "below 4.5e-4, tracked accurately (Figs. 10, 23)", "max_abs_lateral_error_m"),
    ],
    "paper-exp5-hard": [
        ("min clearance [m]", "obstacle avoided, no clearance figure given (Fig. 13)", "min_obstacle_clearance_m"),
        ("max |steering| [rad]", "harsh steering near the obstacle, up to about 50 deg, 0.87 (Fig. 21)", "max_abs_steer_rad"),
    ],
    "paper-exp5-potential": [
        ("min clearance [m]", "could not be implemented in YALMIP", "min_obstacle_clearance_m"),
    ],
    "paper-exp5-gaussian": [
        ("min clearance [m]", "could not be implemented in YALMIP (cost map only, Fig. 14)", "min_obstacle_clearance_m"),
    ],
    "paper-exp5-corridor": [
        ("min clearance [m]", "future work ('safe driving envelopes')", "min_obstacle_clearance_m"),
    ],
    "paper-smoothing": [
        ("max |steering| [rad]", "smoother steering than without Rc (Fig. 12)", "max_abs_steer_rad"),
        ("steering total variation [rad]", "reduced (Fig. 12)", "steer_total_variation_rad"),
    ],
}

#: pairs of runs whose steering traces are overlaid in the report (the paper's Fig. 12)
STEERING_COMPARISONS: dict[str, tuple[str, str]] = {
    "smoothing": ("paper-exp2", "paper-smoothing"),
}

#: runs whose trajectories are overlaid in the report
TRAJECTORY_OVERLAYS: dict[str, tuple[str, ...]] = {
    "exp5": ("paper-exp5-hard", "paper-exp5-corridor", "paper-exp5-potential", "paper-exp5-gaussian"),
}
