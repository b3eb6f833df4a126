"""companion-bench's report (``landfall-bench/1`` results to ``report.html`` and its PNG figures):
:mod:`~landfall_eval.report.page` writes the page and its sections, from the episodes as
:mod:`~landfall_eval.report.episodes` reads them, with :mod:`~landfall_eval.report.markup` (HTML) and
:mod:`~landfall_eval.report.figures` (matplotlib)."""

from landfall_eval.report.episodes import MatplotlibUnavailable, ReportError
from landfall_eval.report.page import write_episode_report, write_report

__all__ = ["MatplotlibUnavailable", "ReportError", "write_episode_report", "write_report"]
