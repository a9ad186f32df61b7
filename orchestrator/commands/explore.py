"""Provides `linkevo explore`: an offline HTML page to browse repertoires and pick a design."""

from __future__ import annotations

import argparse
from pathlib import Path

from linkevo.orchestrator.cli import CliError
from linkevo.orchestrator.commands import options


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the `explore` subcommand."""
    parser = subparsers.add_parser(
        "explore",
        help="write an offline HTML page to browse a repertoire (or a grid's) and pick a cell",
        description=(
            "Write one self-contained HTML page for REF: a trial's repertoire (RUN_ID), or "
            "every repertoire trial of a grid (GRID_ID) behind a trial picker. The page shows "
            "the map of loss (4-D maps folded, the folding chosen on the page), each cell's "
            "linkage, animated foot path and physical checks, filters on the checks, and for "
            "a clicked cell its build sheet and `linkevo pull` command. The page is also "
            "logged as explorer.html to the trial's run (a grid's: its parent run), so it "
            "opens in the MLflow UI."
        ),
    )
    parser.add_argument("ref", help="a repertoire trial's RUN_ID, or a GRID_ID")
    parser.add_argument(
        "--drawn",
        type=int,
        default=None,
        metavar="K",
        help="draw the linkages of each trial's K lowest-loss cells only (default: every "
        "cell of a trial; the 500 best per trial on a grid's page, which makes the page of "
        "a study-budget grid about 33 MB)",
    )
    options.store(parser)
    parser.add_argument(
        "--out", type=Path, default=None, help="the page (default: reports/explore/REF.html)"
    )
    parser.add_argument("--no-log", action="store_true", help="do not log the page to MLflow")
    options.force(parser, "replace an existing --out page (the default page is always redrawn)")
    parser.set_defaults(func=handle)


def handle(args: argparse.Namespace) -> int:
    """Handles `linkevo explore`."""
    import os
    import sys

    from linkevo.orchestrator.explore import GRID_DRAWN, explore
    from linkevo.workers.store import run_layout as layout
    from linkevo.workers.store.runs import RunStore

    if args.drawn is not None and args.drawn < 1:
        raise CliError(f"--drawn {args.drawn}: give the number of cells to draw, >= 1")
    if args.out is not None:
        out = options.output_file(args.out, force=args.force, suffix=".html")
    else:
        out = options.output_folder(Path("reports") / "explore") / f"{args.ref}.html"
    store = RunStore.open(args.tracking_uri, args.experiment)
    found = store.repertoires(args.ref)
    trials, grid_id, parent = found.trials, found.grid_id, found.parent_run_id
    if parent is None:
        log_to, drawn = args.ref, args.drawn
        title = f"linkevo explorer: {trials[0].trial_key} (run {args.ref})"
    else:
        log_to = parent
        drawn = args.drawn if args.drawn is not None else GRID_DRAWN
        title = f"linkevo explorer: grid {grid_id} ({len(trials)} repertoire trials)"
    out.parent.mkdir(parents=True, exist_ok=True)
    os.environ["MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR"] = "false"  # one line per trial instead

    def progress(done: int, trial) -> None:
        print(f"[{done}/{len(trials)}] {trial.trial_key} (run {trial.run_id})", file=sys.stderr)

    log_to = None if args.no_log else log_to
    explore(store, trials, out, title=title, drawn=drawn, log_to=log_to, progress=progress)
    print(out)
    if log_to is not None:
        print(f"logged as {layout.EXPLORER_HTML} to run {log_to}")
    return 0
