"""The core packages type-check: ``mypy`` with the configuration in pyproject.toml (the files it
lists: units, types, models, paths, scene, ocp, solvers, control, and the metrics and verdicts
of sim) reports no error.

Skipped where mypy is not installed (it comes with the ``lint`` extra); CI runs it as well."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_core_packages_type_check():
    pytest.importorskip("mypy", reason="mypy is in the lint extra: pip install -e '.[lint]'")
    r = subprocess.run(
        [sys.executable, "-m", "mypy", "--no-error-summary"], cwd=ROOT, capture_output=True, text=True, timeout=600
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.strip() == "", r.stdout
