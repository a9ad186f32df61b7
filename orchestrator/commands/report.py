"""Provides `linkevo report`: a grid's figures, statistics and findings from MLflow."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from linkevo.orchestrator.cli import CliError
from linkevo.orchestrator.commands import options
from linkevo.workers.store import run_layout as layout

"""What a grid id may hold (it goes into an MLflow filter string)."""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the `report` subcommand."""
    parser = subparsers.add_parser(
        "report",
        help="build a grid's comparison figures, statistics and findings from MLflow",
        description=(
            "Reads a grid's trial runs from MLflow and writes PNG/PDF figures, CSV tables "
            "and one self-contained report.html, also logged under report/ in the grid's "
            "parent run."
        ),
    )
    which = parser.add_mutually_exclusive_group(required=True)
    which.add_argument("grid_id", nargs="?", help="the grid id (tag grid_id of its runs)")
    which.add_argument("--latest", action="store_true", help="report the latest grid")
    options.store(parser)
    parser.add_argument(
        "--out", type=Path, default=None, help="output folder (default: reports/<grid_id>)"
    )
    parser.add_argument(
        "--no-log", action="store_true", help="do not log the report to the grid's parent run"
    )
    parser.add_argument(
        "--trials",
        type=int,
        default=None,
        metavar="N",
        help="report only the first N trials of each approach and fitness (a grown grid's "
        "answer at N trials; logged under report-first<N>/) (default: all)",
    )
    parser.set_defaults(func=handler)

    compare = subparsers.add_parser(
        "compare",
        help="put two grids' best losses side by side, per approach and fitness",
        description=(
            "For every approach and fitness two grids share (paper against legacy mode, "
            "two budgets, ...): each grid's median best loss, the difference and a "
            "Mann–Whitney U test between the two, Holm-corrected per fitness. A grid is "
            "its id in the store or the trials.csv of its report (docs/results/*/)."
        ),
    )
    compare.add_argument("grid_a", help="the first grid: its id, or a report's trials.csv")
    compare.add_argument("grid_b", help="the second grid: its id, or a report's trials.csv")
    options.store(compare)
    compare.add_argument(
        "--out", type=Path, default=None, help="also write the table to this CSV (default: none)"
    )
    options.force(compare)
    compare.set_defaults(func=compare_handler)


def handler(args: argparse.Namespace) -> int:
    """Builds the report and prints where it is and the findings' verdicts."""
    from linkevo.orchestrator.report import ReportNotLogged, build_report
    from linkevo.orchestrator.report.build import report_folder
    from linkevo.workers.store.tracking import require_store, resolve_tracking_uri

    if args.grid_id is not None and not layout.ID_PATTERN.fullmatch(args.grid_id):
        raise CliError(
            f"grid id {args.grid_id!r} is invalid; allowed: letters, digits, '.', '_', '-' "
            "(see the grid_id tag of a grid run, or use --latest)"
        )
    if args.trials is not None and args.trials < 1:
        raise CliError(f"--trials {args.trials} is invalid; allowed: an integer >= 1")
    if args.out is not None:
        options.output_folder(args.out)
    uri = require_store(resolve_tracking_uri(args.tracking_uri))
    try:
        result = build_report(
            uri,
            None if args.latest else args.grid_id,
            args.out,
            experiment=args.experiment,
            log_to_mlflow=not args.no_log,
            first_trials=args.trials,
        )
    except ReportNotLogged as exc:
        print(f"linkevo report: {exc}", file=sys.stderr)
        return 1
    print(f"grid {result.grid_id}: report at {result.html}")
    for finding in result.findings:
        print(f"  [{finding.verdict}] {finding.claim} {finding.evidence}")
    if not args.no_log:
        folder = report_folder(args.trials)
        print(f"logged under {folder}/ in parent run {result.parent_run_id}")
    return 0


def compare_handler(args: argparse.Namespace) -> int:
    """Prints the two grids' comparison table (and writes it as CSV with --out)."""
    from linkevo.orchestrator.report.compare import compare_grids, is_trials_csv
    from linkevo.workers.store.artifacts import write_text_atomic
    from linkevo.workers.store.tracking import require_store, resolve_tracking_uri

    if args.out is not None:
        options.output_file(args.out, force=args.force, suffix=".csv")
    uri = None
    for grid in (args.grid_a, args.grid_b):
        if is_trials_csv(grid):
            if not Path(grid).is_file():
                raise CliError(
                    f"trials table {grid!r} does not exist; allowed: a grid id or the "
                    "trials.csv of a report"
                )
        elif not layout.ID_PATTERN.fullmatch(grid):
            raise CliError(f"grid id {grid!r} is invalid; allowed: letters, digits, '.', '_', '-'")
        elif uri is None:
            uri = require_store(resolve_tracking_uri(args.tracking_uri))
    table, unlike = compare_grids(uri, args.grid_a, args.grid_b, args.experiment)
    for warning in unlike:
        print(f"warning: {warning}; the comparison is not like for like", file=sys.stderr)
    if table.empty:
        print(f"grids {args.grid_a} and {args.grid_b} share no finished approach and fitness")
        return 0
    print(f"a = grid {args.grid_a}, b = grid {args.grid_b}; difference = median b - median a")
    print(table.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    if args.out is not None:
        write_text_atomic(args.out, table.to_csv(index=False))
        print(f"written to {args.out}")
    return 0
