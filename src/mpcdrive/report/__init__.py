"""Reports of runs and reproduced experiments (Markdown, interactive HTML); read results, never
solve."""

from mpcdrive.report.html import (
    HtmlRun,
    render_html_report,
    replay_data,
    write_reproduce_html,
    write_run_html,
)
from mpcdrive.report.markdown import (
    PaperValue,
    ReportEntry,
    render_reproduce_report,
    write_reproduce_report,
)

__all__ = [
    "HtmlRun",
    "PaperValue",
    "ReportEntry",
    "render_html_report",
    "render_reproduce_report",
    "replay_data",
    "write_reproduce_html",
    "write_reproduce_report",
    "write_run_html",
]
