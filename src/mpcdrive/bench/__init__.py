"""``mpcdrive bench``: per-step latency on the benchmark problems P1-P4 (docs/benchmarks.md).

The names below load on first use, so that a bench helper with its own dependencies
(``python -m mpcdrive.bench.reactive``, run in an environment without mpcdrive's) can be
imported without the controller.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .problems import PROBLEMS, BenchProblem
    from .runner import format_table, run_bench

__all__ = ["PROBLEMS", "BenchProblem", "format_table", "run_bench"]

_HOME = {"PROBLEMS": "problems", "BenchProblem": "problems", "format_table": "runner", "run_bench": "runner"}


def __getattr__(name: str) -> Any:
    if name not in _HOME:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from importlib import import_module

    return getattr(import_module(f".{_HOME[name]}", __name__), name)
