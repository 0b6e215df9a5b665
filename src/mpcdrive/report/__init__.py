"""Reports of reproduced experiments (Markdown); read results, never solve."""

from mpcdrive.report.markdown import (
    PaperValue,
    ReportEntry,
    render_reproduce_report,
    write_reproduce_report,
)

__all__ = ["PaperValue", "ReportEntry", "render_reproduce_report", "write_reproduce_report"]
