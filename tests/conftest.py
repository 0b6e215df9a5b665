import os
import subprocess
import sys

os.environ.setdefault("MPLBACKEND", "Agg")

import pytest
from hypothesis import settings

# CI runs are reproducible: the same examples every run (locally hypothesis explores freely)
settings.register_profile("ci", derandomize=True, deadline=None)
if os.environ.get("CI"):
    settings.load_profile("ci")


@pytest.fixture
def run_with_empty_numba_cache(tmp_path):
    """Run Python ``code`` in a fresh process whose numba cache is the empty folder ``tmp_path``
    (so it compiles instead of loading); returns its standard output, and fails the test with its
    standard error if the process fails."""

    def run(code: str) -> str:
        env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
        assert proc.returncode == 0, proc.stderr
        return proc.stdout

    return run
