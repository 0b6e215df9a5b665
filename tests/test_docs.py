"""The documents under docs/ state what the code does: checked against the code, so they cannot
drift (the README has its own test, test_readme.py)."""

import re
from pathlib import Path

import pytest

from mpcdrive.experiments import PAPER_EXPERIMENTS
from mpcdrive.scenarios import load_scenario

DOCS = Path(__file__).resolve().parents[1] / "docs"


def _paper_settings_table() -> dict[str, tuple[str, str]]:
    """docs/paper.md's table of settings: controller key -> (the paper's value, the scenarios')."""
    text = (DOCS / "paper.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\| `controller\.([a-z_]+)` \| `([a-z_0-9]+)`[^|]*\| `([a-z_0-9]+)`[^|]*\|$", text, re.M)
    assert rows, "docs/paper.md has no table of the paper scenarios' settings"
    return {key: (paper, ours) for key, paper, ours in rows}


@pytest.mark.parametrize("sid", PAPER_EXPERIMENTS)
def test_docs_paper_states_the_settings_each_paper_scenario_runs_with(sid):
    controller = load_scenario(sid).controller
    for key, (paper, ours) in _paper_settings_table().items():
        assert getattr(controller, key) == ours, (
            f"{sid}: controller.{key} is {getattr(controller, key)!r}, docs say {ours!r}"
        )
        assert paper in type(controller).model_fields[key].annotation.__args__, f"controller.{key}: no value {paper!r}"
