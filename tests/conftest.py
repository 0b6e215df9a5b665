import os

os.environ.setdefault("MPLBACKEND", "Agg")

from hypothesis import settings

# CI runs are reproducible: the same examples every run (locally hypothesis explores freely)
settings.register_profile("ci", derandomize=True, deadline=None)
if os.environ.get("CI"):
    settings.load_profile("ci")
