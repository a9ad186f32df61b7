"""Provides `linkevo pull`: fetch a tracked linkage with its drawings and build sheet."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from linkevo.orchestrator.cli import CliError
from linkevo.orchestrator.commands import options
from linkevo.workers.store import run_layout as layout

if TYPE_CHECKING:
    from linkevo.workers.store.runs import RunStore


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the `pull` subcommand."""
    parser = subparsers.add_parser(
        "pull",
        help="fetch a linkage, its drawings and LEGO build sheet from MLflow",
        description=(
            "Write linkage.json, linkage.png and build_sheet.md/.csv for RUN_ID (a "
            "trial's best linkage), RUN_ID:CELL or RUN_ID:B0,B1,... (one repertoire cell, "
            "by flat index or bin coordinates), or with --best, the best buildable design of grid "
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
    parser.add_argument(
        "--best",
        action="store_true",
        help="REF is a grid id: take its best buildable design (see --any)",
    )
    parser.add_argument(
        "--any", action="store_true", help="with --best: the best design, buildable or not"
    )
    parser.add_argument("--approach", help="with --best: only this approach")
    parser.add_argument("--fitness", help="with --best: only this fitness")
    options.store(parser)
    parser.add_argument("--out", type=Path, default=None, help="output folder (default pulled)")
    parser.add_argument("--gif", action="store_true", help="also animate one crank turn")
    parser.set_defaults(func=handle)


def grid_trials(store: RunStore, grid_id: str, approach: str | None, fitness: str | None):
    """Returns the grid's FINISHED trials with a best loss, lowest first (of one approach
    and fitness when given).

    Raises:
        NotFound: naming an unknown experiment or grid with the grids there are.
        CliError: naming an unknown approach or fitness with the valid choices, or asking
            for --fitness when the grid has more than one.
    """
    store.grid(grid_id)
    trials = store.trial_runs(grid_id, status="FINISHED")
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
    return sorted(kept, key=lambda r: (r.data.metrics["best_loss"], r.info.run_id))


def best_design(store: RunStore, trials: list) -> tuple[str, str, list[str]]:
    """Returns (linkage reference, what it is, what was passed over) for the lowest-loss
    buildable design among `trials` (lowest best loss first).

    A trial offers its best linkage and, when that is not buildable and the trial keeps a
    repertoire, its lowest-loss buildable cell; trials are read until none left can beat
    the design found. Buildable is `sim.linkage.physical`'s verdict (it turns fully, no toggle,
    transmission angles above the limit).

    A walking trial (F_w) offers its best linkage when it walks without breaking: its
    loss is minus its worse floor's distance, so the lowest is the best walker.

    Raises:
        CliError: no trial offers a buildable design.
    """
    from linkevo.orchestrator.pull import checks_line
    from linkevo.sim.linkage.linkage_doc import from_document, to_document
    from linkevo.sim.robot.walk_fitness import SOUND_BELOW
    from linkevo.sim.study import REPERTOIRE_APPROACHES, WALKING_FITNESS
    from linkevo.workers.store.linkages import LinkageRef, list_cells, load_source

    found: tuple[float, str, str] | None = None
    passed_over = []
    for run in trials:
        loss, run_id = run.data.metrics["best_loss"], run.info.run_id
        if found is not None and loss >= found[0]:
            break
        key = run.data.tags.get(layout.TRIAL_KEY, run_id)
        if run.data.tags.get(layout.FITNESS) == WALKING_FITNESS:  # its best is its best walker
            if loss >= SOUND_BELOW:
                passed_over.append(f"{key}: no walker that does not break (loss {loss:.6g})")
                continue
            what = f"{key}'s best walker (run {run_id}), {-loss:.1f} cm in 10 s on its worse floor"
            found = (loss, run_id, what)
            break
        genome, mode = from_document(load_source(store, LinkageRef(run_id)).document)
        checks = to_document(genome, mode)["checks"]
        if checks["buildable"]:
            found = (loss, run_id, f"{key}'s best linkage (run {run_id}), loss {loss:.6g}")
            break
        passed_over.append(f"{key}'s best linkage, loss {loss:.6g}: {checks_line(checks)}")
        if run.data.tags.get(layout.APPROACH) in REPERTOIRE_APPROACHES:
            cells = list_cells(store, run_id, 1, mode, buildable=True)
            if not cells.empty and (found is None or cells.loss[0] < found[0]):
                cell = int(cells.cell[0])
                what = f"{key}'s cell {cell} (run {run_id}), loss {cells.loss[0]:.6g}"
                found = (float(cells.loss[0]), f"{run_id}:{cell}", what)
    if found is None:
        raise CliError(
            f"no buildable design among the {len(trials)} trials' best linkages and "
            "repertoires; pass --any for the best design regardless"
        )
    return found[1], found[2], passed_over


def handle(args: argparse.Namespace) -> int:
    """Handles `linkevo pull`."""
    from linkevo.orchestrator.pull import (
        confirmed_line,
        confirmed_walk,
        predicted_walks,
        prediction_line,
        pull,
        simulated_walks,
        walk_line,
    )
    from linkevo.workers.store.linkages import LinkageRef, load_source
    from linkevo.workers.store.runs import RunStore

    _refuse_ignored(args)
    store = RunStore.open(args.tracking_uri, args.experiment)
    text = args.ref
    if args.best:
        trials = grid_trials(store, args.ref, args.approach, args.fitness)
        if args.any:
            text = trials[0].info.run_id
            key = trials[0].data.tags.get(layout.TRIAL_KEY)
            loss = trials[0].data.metrics["best_loss"]
            print(
                f"best design of grid {args.ref}, buildable or not: {key}'s best linkage "
                f"(run {text}), loss {loss:.6g}",
                file=sys.stderr,
            )
        else:
            text, what, passed_over = best_design(store, trials)
            print(f"best buildable design of grid {args.ref}: {what}", file=sys.stderr)
            for line in passed_over:
                print(f"  passed over {line}", file=sys.stderr)
    ref = LinkageRef.parse(text)
    if args.list is not None:
        return _print_cells(store, ref, args.list, args.buildable)
    source = load_source(store, ref)
    cell = "its best linkage" if source.cell is None else f"cell {source.cell}"
    if source.predicted:
        cell += " of its prediction map (SAIL: predicted, never walked)"
    print(
        f"pulling run {source.run_id} ({source.approach}, {source.fitness}), {cell}",
        file=sys.stderr,
    )
    walks = simulated_walks(store, source)
    if walks:
        print(f"simulated walk: {walk_line(walks)}", file=sys.stderr)
    confirmed = confirmed_walk(store, source)
    if confirmed:
        print(f"confirmed walk: {confirmed_line(confirmed)}", file=sys.stderr)
    predicted = predicted_walks(store, source)
    if predicted:
        print(f"predicted walk: {prediction_line(predicted)}", file=sys.stderr)
    out = args.out or Path("pulled")
    pulled = pull(source, out, gif=args.gif, walks=walks, predicted=predicted, confirmed=confirmed)
    for path in pulled:
        print(path)
    return 0


def _refuse_ignored(args: argparse.Namespace) -> None:
    """Raises CliError for an option that the other options given would leave unused."""
    needs = {
        "--buildable": (args.buildable, args.list is not None, "--list"),
        "--any": (args.any, args.best, "--best"),
        "--approach": (args.approach is not None, args.best, "--best"),
        "--fitness": (args.fitness is not None, args.best, "--best"),
        "--out": (args.out is not None, args.list is None, "no --list (--list only prints)"),
        "--gif": (args.gif, args.list is None, "no --list (--list only prints)"),
    }
    for option, (given, allowed, what) in needs.items():
        if given and not allowed:
            raise CliError(f"{option} works only with {what}")


def _print_cells(store: RunStore, ref, top: int, buildable: bool) -> int:
    """Prints a run's best repertoire cells with their checks (`linkevo pull RUN --list`)."""
    from linkevo.workers.store.linkages import list_cells

    if top < 1:
        raise CliError(f"--list {top}: give the number of cells to list, >= 1")
    if ref.cell is not None or ref.bins is not None:
        raise CliError("--list takes a run id (RUN_ID), not a cell")
    mode = store.params(ref.run_id).get("mode", "paper")
    table = list_cells(store, ref.run_id, top, mode, buildable)
    if table.empty:
        print(f"run {ref.run_id}: no {'buildable ' if buildable else ''}cell")
        return 0
    print(table.to_string(index=False, float_format=lambda v: f"{v:.3f}"))
    print(f"pull one with: linkevo pull {ref.run_id}:CELL  (or {ref.run_id}:B0,B1,...)")
    return 0
