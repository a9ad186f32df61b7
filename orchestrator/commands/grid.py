"""Provides `linkevo grid` (run a grid of trials on Ray) and `linkevo ui` (the MLflow UI)."""

from __future__ import annotations

import argparse
import json
import signal
import sys
from typing import TYPE_CHECKING

from linkevo.orchestrator.commands import options
from linkevo.orchestrator.commands.options import linkevo_command

if TYPE_CHECKING:
    from linkevo.orchestrator.config import GridConfig
    from linkevo.orchestrator.driver import GridResult
    from linkevo.orchestrator.grid import Grid
    from linkevo.orchestrator.reservation import Cluster


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the `grid` and `ui` subcommands."""
    grid = subparsers.add_parser(
        "grid",
        help="run a grid of trials on Ray, tracked in MLflow",
        description="Run every trial of a grid config on Ray (a local instance, or the "
        "cluster at --address / RAY_ADDRESS), one nested MLflow run per trial.",
    )
    grid.add_argument("config", help="grid config TOML, e.g. configs/quick.toml")
    grid.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a config key with a TOML value, e.g. --set trials=3 "
        '--set \'approaches=["EA","MAP-LIS"]\' (repeatable)',
    )
    options.tracking_uri(
        grid,
        "MLflow tracking URI (http://host:port, sqlite:///abs/path.db) or a folder for "
        "an embedded store; default: config key tracking_uri, MLFLOW_TRACKING_URI, runs/",
    )
    options.ray_address(grid)
    grid.add_argument(
        "--resume",
        action="store_true",
        help="complete an earlier launch: skip FINISHED trials, rerun the rest",
    )
    grid.add_argument(
        "--restart-trial",
        dest="restart",
        action="append",
        default=[],
        metavar="KEY",
        help="with --resume: discard trial KEY's checkpoint (e.g. MAP-LIS/Fp/03) and run it "
        "afresh (repeatable; default: none)",
    )
    grid.add_argument(
        "--dry-run",
        action="store_true",
        help="print the resolved config and the trials, start nothing",
    )
    grid.add_argument(
        "--max-concurrent-trials",
        type=int,
        metavar="N",
        help="trials in flight at once (default: config key max_concurrent_trials)",
    )
    grid.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    grid.set_defaults(func=run_grid)


def run_grid(args: argparse.Namespace) -> int:
    """Runs (or with --dry-run describes) a grid; exit 1 when any trial failed."""
    from linkevo.orchestrator import config as grid_config
    from linkevo.orchestrator.grid import Grid

    overrides = list(args.overrides)
    if args.tracking_uri is not None:
        overrides.append(f"tracking_uri={json.dumps(args.tracking_uri)}")
    if args.max_concurrent_trials is not None:
        overrides.append(f"max_concurrent_trials={args.max_concurrent_trials}")
    grid = Grid.from_config(grid_config.load(args.config, overrides))
    if args.dry_run:
        from linkevo.orchestrator.launch_checks import check_store, trial_specs
        from linkevo.orchestrator.ray_connection import dry_run_cluster
        from linkevo.workers.store.tracking import resolve_tracking_uri

        trial_specs(grid)  # refuses what the launch would refuse
        uri = resolve_tracking_uri(grid.config.tracking_uri or None)
        check_store(uri)
        if grid.config.seed_from:  # the warm start is read as the launch reads it
            from linkevo.orchestrator.launch_checks import check_seed
            from linkevo.workers.store.runs import RunStore

            check_seed(RunStore.open(uri, grid.config.experiment), grid.config.seed_from)
        print(describe(grid, dry_run_cluster(args.address)))
        return 0
    from linkevo.orchestrator import driver
    from linkevo.orchestrator.fan_out import GridInterrupted
    from linkevo.workers.store.outage import ServerLost

    try:
        result = driver.launch(
            grid,
            resume=args.resume,
            restart=tuple(args.restart),
            address=args.address,
            progress=not args.no_progress,
        )
    except GridInterrupted as exc:
        print(
            f"linkevo grid: {exc}.\nComplete the grid with:  {_resume_command(args)}",
            file=sys.stderr,
        )
        return 128 + int(getattr(signal, exc.signal_name))
    except ServerLost as exc:
        print(
            f"linkevo grid: stopped: {exc}. The trials in flight were stopped; their runs "
            "stay RUNNING until the resume marks them KILLED and continues them from their "
            f"checkpoints.\nOnce the server answers, complete the grid with:  "
            f"{_resume_command(args)}",
            file=sys.stderr,
        )
        return 1
    print(summary(result, grid.config))
    print(
        f"\nResults are in MLflow ({result.tracking_uri}), experiment '{grid.config.experiment}'."
    )
    print(f"Open the UI with:  {linkevo_command('ui', *_ui_flag(result.tracking_uri))}")
    return 1 if result.failed else 0


def _resume_command(args: argparse.Namespace) -> str:
    """Returns the command line that completes this grid: the same config and options,
    with --resume."""
    words = ["grid", str(args.config)]
    for override in args.overrides:
        words += ["--set", override]
    for flag, value in (("--tracking-uri", args.tracking_uri), ("--address", args.address)):
        if value is not None:
            words += [flag, value]
    return linkevo_command(*words, "--resume")


def _ui_flag(uri: str) -> list[str]:
    from linkevo.workers.store.tracking import default_tracking_uri

    return [] if uri == default_tracking_uri() else ["--tracking-uri", uri]


def describe(grid: Grid, cluster: Cluster) -> str:
    """Returns the dry-run text: resolved config, grid id, reservation and every trial."""
    from linkevo.orchestrator.config import to_toml
    from linkevo.orchestrator.reservation import Reservation

    cfg = grid.config
    reservation = Reservation.plan(cfg, len(grid.cells), cluster)
    where = "this machine" if cluster.local else "the Ray cluster"
    lines = [
        to_toml(cfg).rstrip(),
        "",
        f"grid {grid.grid_id}  code {grid.code_version}  {len(grid.cells)} trials",
        f"on {where} ({cluster.total_cpus:g} CPU): {reservation.describe()}",
        "",
        f"{'trial key':<20} {'seed':>10}",
    ]
    lines += [f"{cell.key:<20} {cell.seed:>10}" for cell in grid.cells]
    return "\n".join(lines)


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{value:.4g}"


def summary(result: GridResult, config: GridConfig) -> str:
    """Returns the end-of-grid table: per cell trials finished and best loss (min, median),
    then every failed trial with its error."""
    from linkevo.orchestrator.grid_run import cell_summaries

    lines = [
        f"grid {result.grid_id}: {len(result.outcomes) - len(result.failed)}/"
        f"{len(result.outcomes)} trials finished ({len(result.skipped)} already finished "
        f"before this launch), {len(result.failed)} failed, {result.seconds:.0f} s",
        "",
        f"{'approach':<9} {'fitness':<7} {'finished':>8} {'best loss min':>14} {'median':>10}",
    ]
    for row in cell_summaries(config, result.outcomes):
        done = f"{row['finished']}/{row['trials']}"
        lines.append(
            f"{row['approach']:<9} {row['fitness']:<7} {done:>8} "
            f"{_fmt(row['best_loss_min']):>14} {_fmt(row['best_loss_median']):>10}"
        )
    cut = [o.trial_key for o in result.outcomes if o.stopped_by == "max_seconds"]
    if cut:
        lines += [
            "",
            f"{len(cut)} trial(s) stopped by max_seconds before their budget: {', '.join(cut)}",
        ]
    if result.failed:
        lines += ["", "failed trials:"]
        lines += [f"  {o.trial_key:<18} {o.error or o.status}" for o in result.failed]
    return "\n".join(lines)
