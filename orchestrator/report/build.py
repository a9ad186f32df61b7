"""Provides `build_report`: a grid's figures, tables, findings and HTML, logged to MLflow."""

from __future__ import annotations

import contextlib
import io
import json
import os
import secrets
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd
from matplotlib import rc_context

from linkevo.orchestrator.config import ConfigError, from_dict, to_toml
from linkevo.orchestrator.report import figures as fig
from linkevo.orchestrator.report.checks import (
    best_linkage_checks,
    checks_summary,
    walking_winners,
)
from linkevo.orchestrator.report.findings import MEASURES, check_findings
from linkevo.orchestrator.report.html import render_html
from linkevo.orchestrator.report.load import GridData, load_grid, merge_grids
from linkevo.orchestrator.report.measures import best_path_sizes, trial_measures
from linkevo.orchestrator.report.stats import pairwise_tests, summary_table
from linkevo.orchestrator.report.verdicts import Finding
from linkevo.sim.errors import LinkevoError
from linkevo.workers.store.artifacts import write_bytes_atomic
from linkevo.workers.store.runs import RunStore

REPORT_ARTIFACT_DIR = "report"
"""Where the report lands among the grid parent run's artefacts."""


def report_folder(first_trials: int | None) -> str:
    """Returns the parent run's artefact folder of a report (of the first N trials)."""
    return REPORT_ARTIFACT_DIR if first_trials is None else f"report-first{first_trials}"


PNG_DPI = 150
LOGGED_COLUMNS: tuple[str, ...] = (
    "best_loss",
    "coverage",
    "qd_score",
    "common_coverage",
    "common_qd_score",
    "path_diversity",
    "final_evaluations",
)
"""The numbers of `trials.csv` each trial logs itself (the `MEASURES` are computed from
its history and archive by the report)."""
TRIAL_COLUMNS: tuple[str, ...] = (
    "trial_key",
    "approach",
    "fitness",
    "trial_index",
    "seed",
    "run_id",
    "status",
    "error",
    *LOGGED_COLUMNS,
    *MEASURES,
)


@dataclass(frozen=True)
class ReportResult:
    """What `build_report` produced.

    Attributes:
        grid_id: the grid reported on.
        parent_run_id: the grid's parent run (the report is logged there when asked).
        out_dir: the folder holding every file.
        html: the self-contained report page.
        files: every file written, in order.
        summary: `stats.summary_table` of the grid.
        tests: `stats.pairwise_tests` of the grid.
        findings: the study's findings checked on the grid.
    """

    grid_id: str
    parent_run_id: str
    out_dir: Path
    html: Path
    files: tuple[Path, ...]
    summary: pd.DataFrame
    tests: pd.DataFrame
    findings: tuple[Finding, ...]


def config_toml(config: dict) -> str:
    """Returns the grid's config as TOML (as `linkevo grid --dry-run` prints it), or as
    JSON when it is not a loadable config (a grid from an older linkevo)."""
    try:
        return to_toml(from_dict(config))
    except (ConfigError, TypeError, ValueError):
        return json.dumps(config, indent=1, sort_keys=True)


def _render(figure, fmt: str) -> bytes:
    buffer = io.BytesIO()
    figure.savefig(buffer, format=fmt, dpi=PNG_DPI)
    return buffer.getvalue()


def report_figures(grid: GridData) -> list[fig.ReportFigure]:
    """Returns every figure the grid supports, in report order."""
    with rc_context(fig.REPORT_RC):
        made = [fig.best_loss_figure(grid), fig.repertoire_maps_figure(grid)]
        made += [fig.path_maps_figure(grid, fitness) for fitness in grid.fitnesses()]
        made.append(fig.convergence_figure(grid))
    return [f for f in made if f is not None]


def build_report(
    tracking_uri: str,
    grid_id: str | None,
    out_dir: Path | None = None,
    *,
    experiment: str = "linkevo",
    log_to_mlflow: bool = True,
    first_trials: int | None = None,
    more_grids: Sequence[str] = (),
) -> ReportResult:
    """Returns the report of one grid (None: the latest), written to `out_dir`.

    Writes `<name>.png` and `<name>.pdf` per figure, `trials.csv`, `best_loss_summary.csv`,
    `pairwise_tests.csv`, `findings.csv`, `best_linkage_checks.csv` (the physical checks of
    each trial's best linkage), `path_sizes.csv` (each trial's best-ever foot path's
    size, `measures.best_path_sizes`), `walking_winners.csv` (a walking grid's best walkers,
    `checks.walking_winners`) and `report.html`, and logs them all under
    `report/` in the grid's parent run. `out_dir` defaults to `reports/<grid_id>`.
    With `first_trials` = N only trial indices 0..N-1 of each cell count (a grid grown by
    `--resume --set trials=...` answered at its first N trials); the report goes to
    `reports/<grid_id>-first<N>` and `report-first<N>/`. With `more_grids`, those grids
    are reported with the first as one study (`load.merge_grids`: a study split into grids
    by approach or fitness), in `reports/<id>+<id>...`, logged in the first's parent run.
    """
    with tempfile.TemporaryDirectory(prefix="linkevo-report-") as cache:
        grid = merge_grids(
            [
                load_grid(tracking_uri, g, Path(cache) / str(i), experiment, first_trials)
                for i, g in enumerate([grid_id, *more_grids])
            ]
        )
        name = grid.grid_id if first_trials is None else f"{grid.grid_id}-first{first_trials}"
        out = Path(out_dir) if out_dir is not None else Path("reports") / name
        summary = summary_table(grid.trials)
        tests = pairwise_tests(grid.trials)
        measured = trial_measures(grid)[["trial_key", *MEASURES]]
        trials = grid.trials.merge(measured, on="trial_key", how="left")
        sizes = best_path_sizes(grid)
        budget = grid.config.get("evaluations")
        findings = tuple(check_findings(trials, sizes, tests, budget))
        checks = best_linkage_checks(grid)
        winners = walking_winners(grid)
        made = report_figures(grid)
    with _staged(out) as staging:
        tables = {"best_linkage_checks.csv": checks, "path_sizes.csv": sizes}
        if len(winners):
            tables["walking_winners.csv"] = winners
        written = _write_report(
            grid, trials, tracking_uri, summary, tests, findings, tables, made, staging
        )
    files = [out / path.name for path in written]
    html_path = out / "report.html"
    if log_to_mlflow:
        store = RunStore(tracking_uri)
        try:
            for path in files:
                store.log_artefact(grid.parent_run_id, path, report_folder(first_trials))
        except Exception as exc:
            raise ReportNotLogged(
                f"the report is complete in {out}, but logging it to parent run "
                f"{grid.parent_run_id} failed ({type(exc).__name__}: {exc}); rerun when the "
                "store is writable, or pass --no-log"
            ) from exc
    return ReportResult(
        grid_id=grid.grid_id,
        parent_run_id=grid.parent_run_id,
        out_dir=out,
        html=html_path,
        files=tuple(files),
        summary=summary,
        tests=tests,
        findings=findings,
    )


class ReportNotLogged(LinkevoError, RuntimeError):
    """The report's folder is written, its logging to MLflow failed; says where it is."""


@contextlib.contextmanager
def _staged(out: Path) -> Iterator[Path]:
    """Yields a new staging folder beside `out`; when the block succeeds, its files are
    moved into `out` one rename each (other files in `out` are left alone), so a report
    that fails half-way (a full disk, an interrupt) leaves the previous one as it was.
    When the block fails, the staging folder is removed."""
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = out.with_name(f".{out.name}.new-{os.getpid()}-{secrets.token_hex(4)}")
    staging.mkdir()
    try:
        yield staging
        out.mkdir(exist_ok=True)
        for path in sorted(staging.iterdir()):
            path.replace(out / path.name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _write_report(
    grid, trials, tracking_uri, summary, tests, findings, read_tables, made, out: Path
) -> list[Path]:
    """Writes the report's files into `out`; returns them (report.html last)."""
    files: list[Path] = []
    embedded = []
    for item in made:
        png = _render(item.figure, "png")
        # The PNG pass placed every axes; keep those positions for the PDF (one layout).
        item.figure.set_layout_engine("none")
        for suffix, data in ((".png", png), (".pdf", _render(item.figure, "pdf"))):
            path = out / f"{item.name}{suffix}"
            write_bytes_atomic(path, data)
            files.append(path)
        embedded.append((item.title, item.caption, png))
    trials = trials.reindex(columns=list(TRIAL_COLUMNS))
    tables = {
        "trials.csv": trials,
        "best_loss_summary.csv": summary,
        "pairwise_tests.csv": tests,
        "findings.csv": pd.DataFrame([f.__dict__ for f in findings]),
        **read_tables,
    }
    for name, table in tables.items():
        path = out / name
        write_bytes_atomic(path, table.to_csv(index=False).encode())
        files.append(path)
    page = render_html(
        grid_id=grid.grid_id,
        parent_run_id=grid.parent_run_id,
        tracking_uri=tracking_uri,
        config=grid.config,
        config_text=config_toml(grid.config),
        figures=embedded,
        summary=summary,
        tests=tests,
        trials=trials,
        findings=findings,
        checks=checks_summary(read_tables["best_linkage_checks.csv"]),
        winners=read_tables.get("walking_winners.csv"),
    )
    html_path = out / "report.html"
    write_bytes_atomic(html_path, page.encode("utf-8"))
    files.append(html_path)
    return files
