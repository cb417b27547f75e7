"""`benchlab report`: the paper's Fig. 3, 4 and 5, residual analysis and a Markdown page of error figures."""

from benchlab.report.build import write_report

__all__ = ["write_report"]
