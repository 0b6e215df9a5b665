"""``mpcdrive bench``: per-step latency on the benchmark problems P1-P4 (docs/benchmarks.md)."""

from .problems import PROBLEMS, BenchProblem
from .runner import format_table, run_bench

__all__ = ["PROBLEMS", "BenchProblem", "format_table", "run_bench"]
