"""Reports an engineer can hand on: one self-contained HTML file and a paginated PDF per run.

    from bayes_amb.report import collect_run, write_report
    result = write_report(collect_run("runs/paper"), "reports/paper")

Sections appear when their inputs are present; nothing estimated is recomputed.
"""

from bayes_amb.report.collect import ReportError, RunData, StudyData, collect_run
from bayes_amb.report.render import PDF_BACKENDS, ReportResult, render_html, write_pdf, write_report
from bayes_amb.report.sections import SECTION_TITLES, ReportOptions, Section, Table

__all__ = ["PDF_BACKENDS", "SECTION_TITLES", "ReportError", "ReportOptions", "ReportResult",
           "RunData", "Section", "StudyData", "Table", "collect_run", "render_html",
           "write_pdf", "write_report"]
