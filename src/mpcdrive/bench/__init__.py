"""``mpcdrive bench``: per-step latency on the PERF.md benchmark problems."""

from .problems import PROBLEMS, BenchProblem
from .runner import format_table, run_bench

__all__ = ["PROBLEMS", "BenchProblem", "format_table", "run_bench"]
