"""The ours-vs-paper table's verdict column: computed from the numbers, with a footnote where
ours differs."""

import re

import pytest

from mpcdrive.experiments import PAPER_EXPERIMENTS, PAPER_VALUES
from mpcdrive.report import ReportEntry, write_reproduce_report
from mpcdrive.report.html import write_reproduce_html
from mpcdrive.report.markdown import PaperFigure, paper_comparison, verdict


@pytest.mark.parametrize(
    "ours, figure, reference, word",
    [
        (1.00, PaperFigure(1.047, "about", lower_is_better=False), None, "matches"),  # 4.5 % off
        (0.90, PaperFigure(1.047, "about", lower_is_better=False), None, "differs"),  # 14 % off
        (0.03, PaperFigure(0.04, "about"), None, "better"),  # an error 25 % below the paper's
        (0.05, PaperFigure(0.04, "about"), None, "differs"),
        (0.0087, PaperFigure(0.008, "at_most"), None, "matches"),  # within 10 % of the bound
        (0.0089, PaperFigure(0.008, "at_most"), None, "differs"),
        (0.0, PaperFigure(0.0, "at_least"), None, "matches"),
        (-0.01, PaperFigure(0.0, "at_least"), None, "differs"),
        (0.07, PaperFigure(kind="lower_than", relative_to="a"), 0.10, "matches"),
        (0.11, PaperFigure(kind="lower_than", relative_to="a"), 0.10, "differs"),
        (0.11, None, None, "no number"),
        (None, PaperFigure(0.04, "about"), None, "not run"),
    ],
)
def test_verdict_rules(ours, figure, reference, word):
    got, reason = verdict(ours, figure, reference)
    assert got == word
    assert bool(reason) == (word == "differs")


def test_bad_paper_figures_are_refused():
    with pytest.raises(ValueError, match="kind"):
        PaperFigure(1.0, "roughly")
    with pytest.raises(ValueError, match="value"):
        PaperFigure(kind="about")
    with pytest.raises(ValueError, match="relative_to"):
        PaperFigure(1.0, "lower_than")


PAPER = {
    "a": [
        (
            "max |e_y| [m]",
            "up to 0.04",
            "max_abs_lateral_error_m",
            PaperFigure(0.04, "about", note="the noise models differ"),
        ),
        ("max |steer| [rad]", "1.047", "max_abs_steer_rad", PaperFigure(1.047, "about", lower_is_better=False)),
        ("final [m]", "converges", "final_lateral_error_m"),
    ],
    "b": [
        ("max |e_y| [m]", "below 0.01", "max_abs_lateral_error_m", PaperFigure(0.01, "at_most")),
        ("final [m]", "better than a", "final_lateral_error_m", PaperFigure(kind="lower_than", relative_to="a")),
    ],
    "c": [("max |e_y| [m]", "small", "max_abs_lateral_error_m", PaperFigure(0.01, "at_most"))],
}
ENTRIES = [
    ReportEntry("a", "", {"max_abs_lateral_error_m": 0.28, "max_abs_steer_rad": 1.0, "final_lateral_error_m": 0.1}),
    ReportEntry("b", "", {"max_abs_lateral_error_m": 0.02, "final_lateral_error_m": 0.05}),
]


def test_table_has_a_verdict_column_and_footnotes():
    header, rows, notes = paper_comparison(ENTRIES, PAPER)
    assert header[-1] == "verdict"
    verdicts = {(r[0], r[1]): r[-1] for r in rows}
    assert verdicts[("a", "max |e_y| [m]")] == "differs [1]" and notes[0] == "the noise models differ"
    assert verdicts[("a", "max |steer| [rad]")] == "matches"
    assert verdicts[("a", "final [m]")] == "no number"
    assert verdicts[("b", "max |e_y| [m]")] == "differs [2]" and "2x the paper's bound 0.01" in notes[1]
    assert verdicts[("b", "final [m]")] == "matches"  # 0.05 < a's 0.1
    assert verdicts[("c", "max |e_y| [m]")] == "not run"
    assert len(notes) == 2


def test_markdown_and_html_show_the_verdicts_and_the_footnotes(tmp_path):
    md = write_reproduce_report(tmp_path, ENTRIES, PAPER).read_text()
    assert "| experiment | quantity | paper | ours | verdict |" in md
    assert "| `a` | max \\|e_y\\| [m] | up to 0.04 | 0.28 | differs [1] |" in md
    assert "[1] the noise models differ" in md and "within 10 %" in md
    html = write_reproduce_html(
        tmp_path, [{"id": e.id, "description": "", "metrics": e.metrics, "figures": []} for e in ENTRIES], PAPER
    ).read_text(encoding="utf-8")
    assert "<th>verdict</th>" in html and "<td>differs [1]</td>" in html
    assert re.search(r'<p class="note">\[1\] the noise models differ</p>', html)


def test_every_paper_experiment_has_rows_and_the_disturbance_rows_say_why():
    assert set(PAPER_VALUES) == set(PAPER_EXPERIMENTS)
    for exp_id in ("paper-disturbance-v1", "paper-disturbance-v4"):
        (row,) = PAPER_VALUES[exp_id]
        assert row[3] is not None and "Not comparable" in row[3].note
    # the verdicts of the stored closed-loop tolerances' worst case: the disturbance runs differ
    entries = [
        ReportEntry("paper-disturbance-v1", "", {"max_abs_lateral_error_m": 0.28}),
        ReportEntry("paper-disturbance-v4", "", {"max_abs_lateral_error_m": 0.12}),
    ]
    _, rows, notes = paper_comparison(
        entries, {k: PAPER_VALUES[k] for k in ("paper-disturbance-v1", "paper-disturbance-v4")}
    )
    assert [r[-1] for r in rows] == ["differs [1]", "differs [1]"] and len(notes) == 1
