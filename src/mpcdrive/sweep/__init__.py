"""Monte Carlo robustness sweeps over a scenario: varied initial states, disturbances and model
parameters; runs on a local process pool or a Ray cluster; one results table, a summary that
explains every failed run, and histograms."""

from .runner import (
    METRIC_COLUMNS,
    TIMING_COLUMNS,
    RunTask,
    SuccessCriteria,
    SweepPlan,
    plan_sweep,
    run_sweep,
    run_task,
)
from .summary import result_columns, summarize, summary_markdown, write_sweep_outputs
from .vary import DISTRIBUTIONS, Distribution, Setting, SweepError, Variation, parse_set, parse_vary

__all__ = [
    "DISTRIBUTIONS",
    "METRIC_COLUMNS",
    "TIMING_COLUMNS",
    "Distribution",
    "RunTask",
    "Setting",
    "SuccessCriteria",
    "SweepError",
    "SweepPlan",
    "Variation",
    "parse_set",
    "parse_vary",
    "plan_sweep",
    "result_columns",
    "run_sweep",
    "run_task",
    "summarize",
    "summary_markdown",
    "write_sweep_outputs",
]
