"""Tracks shipped with mpcdrive: CSV waypoint files (x_m, y_m, w_tr_right_m, w_tr_left_m) made by
:mod:`mpcdrive.scenarios.tracks.generate` (``python -m mpcdrive.scenarios.tracks.generate``)."""

from __future__ import annotations

from importlib import resources


def packaged_track_names() -> list[str]:
    """Names of the packaged tracks, sorted."""
    return sorted(p.name[:-4] for p in resources.files(__package__).iterdir() if p.name.endswith(".csv"))


def packaged_track_text(name: str) -> str:
    """CSV text of the packaged track ``name``; ValueError listing the names otherwise."""
    if name not in packaged_track_names():
        raise ValueError(f"no packaged track {name!r} (packaged: {', '.join(packaged_track_names())})")
    return (resources.files(__package__) / f"{name}.csv").read_text(encoding="utf-8")
