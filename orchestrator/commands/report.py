"""Provides `linkevo report` (a grid's figures, statistics and findings from MLflow),
`linkevo compare` (two grids' best losses side by side) and `linkevo findings` (a report's
claims judged again from its folder's tables)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from linkevo.orchestrator.cli import CliError
from linkevo.orchestrator.commands import options
from linkevo.workers.store import run_layout as layout


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
    parser.add_argument(
        "--with",
        dest="more_grids",
        action="append",
        default=[],
        metavar="GRID_ID",
        help="another grid of the same study (split by approach or fitness), reported with "
        "the first as one; its config may differ only in approaches, fitnesses and trials "
        "(repeatable) (default: none)",
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

    findings = subparsers.add_parser(
        "findings",
        help="judge the study's claims again from a report folder's tables alone",
        description=(
            "Recomputes every claim of a report folder (docs/results/*/) from its trials.csv "
            "and path_sizes.csv, with no store, prints the verdicts and says where they "
            "differ from the folder's findings.csv. --measures-from fills the per-trial "
            "measures a trials.csv predates from the report of a rerun of its trials."
        ),
    )
    findings.add_argument("folder", type=Path, help="a report's folder, e.g. docs/results/paper")
    findings.add_argument(
        "--measures-from",
        type=Path,
        action="append",
        default=[],
        metavar="CSV",
        help="the trials.csv of a report of the same trials run again (same seeds); each "
        "rerun trial must log what the published one did (repeatable) (default: none)",
    )
    findings.add_argument(
        "--write",
        action="store_true",
        help="write the folder's findings.csv (and its trials.csv with the measures taken)",
    )
    findings.set_defaults(func=findings_handler)


def handler(args: argparse.Namespace) -> int:
    """Builds the report and prints where it is and the findings' verdicts."""
    from linkevo.orchestrator.report import ReportNotLogged, build_report
    from linkevo.orchestrator.report.build import report_folder
    from linkevo.workers.store.tracking import require_store, resolve_tracking_uri

    for grid_id in [args.grid_id, *args.more_grids]:
        if grid_id is not None and not layout.ID_PATTERN.fullmatch(grid_id):
            raise CliError(
                f"grid id {grid_id!r} is invalid; allowed: letters, digits, '.', '_', '-' "
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
            more_grids=args.more_grids,
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


def findings_handler(args: argparse.Namespace) -> int:
    """Prints a report folder's claims judged from its tables, and where they differ from
    its findings.csv; with --write, writes them (and the measures taken) into the folder."""
    import pandas as pd

    from linkevo.orchestrator.report.compare import read_trials_csv
    from linkevo.orchestrator.report.published import (
        add_measures,
        changed_claims,
        read_folder,
        table_findings,
    )
    from linkevo.workers.store.artifacts import write_text_atomic

    folder = args.folder
    if not (folder / "trials.csv").is_file():
        raise CliError(
            f"{str(folder)!r} holds no trials.csv; allowed: a report's folder "
            "(docs/results/paper, reports/GRID_ID)"
        )
    for path in args.measures_from:
        if not path.is_file():
            raise CliError(
                f"--measures-from {str(path)!r} does not exist; allowed: a report's trials.csv"
            )
    if args.write:
        options.output_folder(folder, "folder")
    trials, sizes = read_folder(folder)
    if args.measures_from:
        reruns = pd.concat([read_trials_csv(str(p)) for p in args.measures_from])
        trials = add_measures(trials, reruns)
    findings = table_findings(trials, sizes)
    for row in findings.itertuples():
        print(f"  [{row.verdict}] {row.number} {row.fitness} {row.claim} {row.evidence}")
    published = folder / "findings.csv"
    if published.is_file():
        changed = changed_claims(findings, pd.read_csv(published, dtype=str))
        print(
            f"{published}: " + ("the same" if not changed else "differs on " + ", ".join(changed))
        )
    if args.write:
        if args.measures_from:
            write_text_atomic(folder / "trials.csv", trials.to_csv(index=False))
        write_text_atomic(published, findings.to_csv(index=False))
        print(f"written to {folder}")
    return 0
