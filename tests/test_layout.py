"""The source layout: no module of the package grows past a size one can read through."""

from __future__ import annotations

from pathlib import Path

MAX_LINES = 800
SRC = Path(__file__).resolve().parents[1] / "src"


def test_no_module_is_over_800_lines():
    sizes = {p: len(p.read_text(encoding="utf-8").splitlines()) for p in sorted((SRC / "mpcdrive").rglob("*.py"))}
    assert len(sizes) > 20  # the package's modules, not an empty folder
    over = {p.relative_to(SRC).as_posix(): n for p, n in sizes.items() if n > MAX_LINES}
    assert not over, f"modules over {MAX_LINES} lines (split them along a seam): " + ", ".join(
        f"{name} ({n})" for name, n in sorted(over.items())
    )
