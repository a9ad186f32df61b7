"""Provides `linkevo pull`: fetch a tracked linkage with its drawings and build sheet."""

from __future__ import annotations

import argparse
from pathlib import Path

from orchestrator.cli import CliError


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the `pull` subcommand."""
    parser = subparsers.add_parser(
        "pull",
        help="fetch a linkage, its drawings and LEGO build sheet from MLflow",
        description=(
            "Write linkage.json, linkage.png and build_sheet.md/.csv for RUN_ID (a "
            "trial's best linkage), RUN_ID:CELL (one repertoire cell), or with --best, "
            "the best trial of grid GRID_ID."
        ),
    )
    parser.add_argument("ref", help="RUN_ID, RUN_ID:CELL, or GRID_ID with --best")
    parser.add_argument("--best", action="store_true", help="REF is a grid id: take its best trial")
    parser.add_argument("--approach", help="with --best: only this approach")
    parser.add_argument("--fitness", help="with --best: only this fitness")
    parser.add_argument("--experiment", default="linkevo")
    parser.add_argument("--tracking-uri", default=None)
    parser.add_argument("--out", type=Path, default=Path("pulled"))
    parser.add_argument("--gif", action="store_true", help="also animate one crank turn")
    parser.set_defaults(func=handle)


def best_trial(client, experiment: str, grid_id: str, approach: str | None, fitness: str | None):
    """Returns the run id of the grid's FINISHED trial with the lowest best_loss."""
    exp = client.get_experiment_by_name(experiment)
    if exp is None:
        raise CliError(f"--experiment {experiment!r} does not exist in this tracking store")
    query = [f"tags.grid_id = '{grid_id}'", "tags.`linkevo.kind` = 'trial'"]
    query += [f"tags.{k} = '{v}'" for k, v in (("approach", approach), ("fitness", fitness)) if v]
    runs = client.search_runs(
        [exp.experiment_id],
        " and ".join([*query, "attributes.status = 'FINISHED'"]),
        order_by=["metrics.best_loss ASC"],
        max_results=1,
    )
    if not runs:
        raise CliError(f"grid {grid_id!r} has no FINISHED trial matching {' and '.join(query)}")
    return runs[0].info.run_id


def handle(args: argparse.Namespace) -> int:
    """Handles `linkevo pull`."""
    from mlflow.tracking import MlflowClient

    from orchestrator.pull import pull
    from workers.linkages import LinkageError, LinkageRef, load_source
    from workers.tracking import resolve_tracking_uri

    client = MlflowClient(tracking_uri=resolve_tracking_uri(args.tracking_uri))
    text = args.ref
    if args.best:
        text = best_trial(client, args.experiment, args.ref, args.approach, args.fitness)
    try:
        source = load_source(client, LinkageRef.parse(text))
    except LinkageError as exc:
        raise CliError(str(exc)) from exc
    for path in pull(source, args.out, gif=args.gif):
        print(path)
    return 0
