"""Results to files: atomic writes, ``trajectory.csv`` and JSON (reads results, never solves)."""

from mpcdrive.io.atomic import atomic_output_dir, atomic_write_bytes, atomic_write_text
from mpcdrive.io.results import (
    TRAJECTORY_COLUMNS,
    read_trajectory_csv,
    to_jsonable,
    trajectory_columns,
    write_json,
    write_trajectory_csv,
)

__all__ = [
    "TRAJECTORY_COLUMNS",
    "atomic_output_dir",
    "atomic_write_bytes",
    "atomic_write_text",
    "read_trajectory_csv",
    "to_jsonable",
    "trajectory_columns",
    "write_json",
    "write_trajectory_csv",
]
