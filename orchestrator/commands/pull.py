"""Provides `linkevo pull`: fetch a tracked linkage with its drawings and build sheet."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from linkevo.orchestrator.cli import CliError
from linkevo.workers.store import run_layout as layout


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the `pull` subcommand."""
    parser = subparsers.add_parser(
        "pull",
        help="fetch a linkage, its drawings and LEGO build sheet from MLflow",
        description=(
            "Write linkage.json, linkage.png and build_sheet.md/.csv for RUN_ID (a "
            "trial's best linkage), RUN_ID:CELL or RUN_ID:B0,B1,... (one repertoire cell, "
            "by flat index or bin coordinates), or with --best, the best trial of grid "
            "GRID_ID. With --list, print the repertoire's best cells and their physical "
            "checks instead."
        ),
    )
    parser.add_argument("ref", help="RUN_ID, RUN_ID:CELL, RUN_ID:B0,B1,..., or GRID_ID with --best")
    parser.add_argument(
        "--list",
        type=int,
        nargs="?",
        const=20,
        default=None,
        metavar="K",
        help="print the K lowest-loss cells (default K: 20) with size and checks",
    )
    parser.add_argument(
        "--buildable", action="store_true", help="with --list: only cells that pass the checks"
    )
    parser.add_argument("--best", action="store_true", help="REF is a grid id: take its best trial")
    parser.add_argument("--approach", help="with --best: only this approach")
    parser.add_argument("--fitness", help="with --best: only this fitness")
    parser.add_argument("--experiment", default="linkevo", help="MLflow experiment")
    parser.add_argument(
        "--tracking-uri",
        default=None,
        help="MLflow tracking URI (default: MLFLOW_TRACKING_URI, else runs/mlflow.db)",
    )
    parser.add_argument("--out", type=Path, default=Path("pulled"), help="output folder")
    parser.add_argument("--gif", action="store_true", help="also animate one crank turn")
    parser.set_defaults(func=handle)


"""What a grid id looks like (the first 12 hex digits of a hash, `docs/grid.md`)."""


def best_trial(client, experiment: str, grid_id: str, approach: str | None, fitness: str | None):
    """Returns the run id of the grid's FINISHED trial with the lowest best_loss.

    Raises:
        CliError: naming an unknown experiment, grid, approach or fitness with the valid
            choices, or asking for --fitness when the grid has more than one.
    """
    exp = client.get_experiment_by_name(experiment)
    if exp is None:
        raise CliError(f"--experiment {experiment!r} does not exist in this tracking store")
    grids = layout.grid_runs(client, exp.experiment_id)
    known = sorted({r.data.tags.get(layout.GRID_ID, "") for r in grids} - {""})
    if not layout.ID_PATTERN.fullmatch(grid_id) or grid_id not in known:
        raise CliError(
            f"no grid {grid_id!r} in experiment {experiment!r}; known grids: "
            f"{', '.join(known) or 'none'}"
        )
    trials = layout.trial_runs(client, exp.experiment_id, grid_id, status="FINISHED")
    choices = {
        key: sorted({r.data.tags.get(key, "") for r in trials} - {""})
        for key in (layout.APPROACH, layout.FITNESS)
    }
    for key, value in (("approach", approach), ("fitness", fitness)):
        if value is not None and value not in choices[key]:
            raise CliError(
                f"--{key} {value!r}: grid {grid_id} has finished trials of "
                f"{', '.join(choices[key]) or 'no ' + key}"
            )
    if fitness is None and len(choices["fitness"]) > 1:
        raise CliError(
            f"grid {grid_id} has trials of {' and '.join(choices['fitness'])}, whose losses "
            f"do not compare; pass --fitness {' or --fitness '.join(choices['fitness'])}"
        )
    kept = [
        r
        for r in trials
        if (approach is None or r.data.tags.get(layout.APPROACH) == approach)
        and (fitness is None or r.data.tags.get(layout.FITNESS) == fitness)
        and "best_loss" in r.data.metrics
    ]
    if not kept:
        raise CliError(f"grid {grid_id} has no finished trial with a best loss to pull")
    best = min(kept, key=lambda r: r.data.metrics["best_loss"])
    return best.info.run_id


def handle(args: argparse.Namespace) -> int:
    """Handles `linkevo pull`."""
    from mlflow.tracking import MlflowClient

    from linkevo.orchestrator.pull import pull
    from linkevo.workers.store.linkages import LinkageError, LinkageRef, load_source
    from linkevo.workers.store.tracking import require_store, resolve_tracking_uri

    client = MlflowClient(tracking_uri=require_store(resolve_tracking_uri(args.tracking_uri)))
    text = args.ref
    if args.best:
        text = best_trial(client, args.experiment, args.ref, args.approach, args.fitness)
        run = client.get_run(text)
        tags = run.data.tags
        print(
            f"best trial of grid {args.ref}: {tags.get('trial_key')} (run {text}), best loss "
            f"{run.data.metrics['best_loss']:.6g}",
            file=sys.stderr,
        )
    try:
        ref = LinkageRef.parse(text)
        if args.list is not None:
            return _print_cells(client, ref, args.list, args.buildable)
        source = load_source(client, ref)
    except LinkageError as exc:
        raise CliError(str(exc)) from exc
    cell = "its best linkage" if source.cell is None else f"cell {source.cell}"
    print(f"pulling run {source.run_id} ({source.approach}, {source.fitness}), {cell}",
          file=sys.stderr)  # fmt: skip
    for path in pull(source, args.out, gif=args.gif):
        print(path)
    return 0


def _print_cells(client, ref, top: int, buildable: bool) -> int:
    """Prints a run's best repertoire cells with their checks (`linkevo pull RUN --list`)."""
    from linkevo.workers.store.linkages import list_cells

    if top < 1:
        raise CliError(f"--list {top}: give the number of cells to list, >= 1")
    if ref.cell is not None or ref.bins is not None:
        raise CliError("--list takes a run id (RUN_ID), not a cell")
    mode = client.get_run(ref.run_id).data.params.get("mode", "paper")
    table = list_cells(client, ref.run_id, top, mode, buildable)
    if table.empty:
        print(f"run {ref.run_id}: no {'buildable ' if buildable else ''}cell")
        return 0
    print(table.to_string(index=False, float_format=lambda v: f"{v:.3f}"))
    print(f"pull one with: linkevo pull {ref.run_id}:CELL  (or {ref.run_id}:B0,B1,...)")
    return 0
