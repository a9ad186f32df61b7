"""Reports: a grid's comparison figures, statistics and findings, read from MLflow."""

from linkevo.orchestrator.report.build import ReportNotLogged, ReportResult, build_report
from linkevo.orchestrator.report.load import GridData, load_grid

__all__ = [
    "GridData",
    "ReportNotLogged",
    "ReportResult",
    "build_report",
    "load_grid",
]
