"""Provides `linkevo walkmap`: every chosen cell of a repertoire (or of each repertoire of
a grid) walked on the simulated robot, fanned out over Ray."""

from __future__ import annotations

import argparse
import math
import signal

from linkevo.orchestrator.cli import CliError
from linkevo.workers.store import run_layout as layout

FLOOR_CHOICES = ("flat", "carpet", "both")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the `walkmap` subcommand."""
    parser = subparsers.add_parser(
        "walkmap",
        help="walk every chosen cell of a repertoire on the simulated robot (a walk map)",
        description=(
            "Walks the robot of every chosen cell of REF's repertoire (a trial's RUN_ID, or "
            "each repertoire trial of a GRID_ID) once for 10 s on each floor in 3-D physics "
            "(docs/walking.md), fanned out over Ray (the legs built, then each distinct leg "
            "walked once), and logs the walk "
            "map to the trial's run: walkmap.parquet (a row per cell and floor: distance, "
            "breaks, reason) and walkmap.png. `linkevo explore` then colours the map by "
            "distance and `linkevo pull` prints a cell's."
        ),
    )
    parser.add_argument("ref", help="a repertoire trial's RUN_ID, or a GRID_ID")
    parser.add_argument("--floor", default="both", help="flat, carpet or both (default: both)")
    parser.add_argument(
        "--cells",
        default="buildable",
        help="buildable (the cells that pass the 2-D physical checks, walked as their LEGO "
        "build; the default), best:K (the K lowest-loss of those) or all (every cell, as "
        "evolved where no LEGO build turns)",
    )
    parser.add_argument("--seconds", type=float, default=10.0, help="seconds per walk")
    parser.add_argument(
        "--resume", action="store_true", help="walk only the cells the run's walk map lacks"
    )
    parser.add_argument("--address", help="Ray address (default: RAY_ADDRESS, else start one)")
    parser.add_argument("--experiment", default="linkevo", help="MLflow experiment")
    parser.add_argument(
        "--tracking-uri",
        default=None,
        help="MLflow tracking URI (default: MLFLOW_TRACKING_URI, else runs/mlflow.db)",
    )
    parser.set_defaults(func=handle)


def handle(args: argparse.Namespace) -> int:
    """Handles `linkevo walkmap`."""
    import sys

    from mlflow.tracking import MlflowClient
    from tqdm import tqdm

    from linkevo.orchestrator.explore import ExploreError, resolve_repertoires
    from linkevo.orchestrator.walkmap import (
        Selection,
        WalkMapError,
        refuse_overwrite,
        run_on_ray,
        walk_map,
    )
    from linkevo.workers.store.tracking import require_store, resolve_tracking_uri

    if args.floor not in FLOOR_CHOICES:
        raise CliError(f"--floor {args.floor!r}: allowed {', '.join(FLOOR_CHOICES)}")
    if not math.isfinite(args.seconds) or not 0 < args.seconds <= 600:
        raise CliError(f"--seconds {args.seconds}: allowed a number in (0, 600]")
    try:
        selection = Selection.parse(args.cells)
    except WalkMapError as exc:
        raise CliError(str(exc)) from exc
    floors = ("flat", "carpet") if args.floor == "both" else (args.floor,)
    client = MlflowClient(tracking_uri=require_store(resolve_tracking_uri(args.tracking_uri)))
    try:
        trials, _, _ = resolve_repertoires(client, args.ref, args.experiment)
        for trial in trials:  # before Ray starts or anything is walked
            refuse_overwrite(client, trial, args.resume)
    except (ExploreError, WalkMapError) as exc:
        raise CliError(str(exc)) from exc

    import ray

    from linkevo.orchestrator.ray_connection import connect_ray
    from linkevo.orchestrator.reservation import Cluster

    started = connect_ray(args.address, Cluster.this_machine())
    in_flight = 2 * int(Cluster.of_ray().total_cpus)
    previous = signal.signal(signal.SIGTERM, _interrupt)  # SIGTERM stops as Ctrl-C does
    try:
        for trial in trials:
            bar = tqdm(desc=f"walkmap {trial.trial_key}", unit="cell", file=sys.stderr)

            def tick(step: str, done: int, total: int, bar=bar, key=trial.trial_key) -> None:
                label = f"walkmap {key}: {step}"
                if bar.desc != label:  # a new step: its own count and rate
                    bar.set_description_str(label, refresh=False)  # drawn by the reset
                    bar.unit = "cell" if step == "building legs" else "walk"
                    bar.reset(total)
                    bar.initial = done  # the rate counts what this step does
                bar.total = total
                bar.n = done
                bar.refresh()

            try:
                frame = walk_map(
                    client,
                    trial,
                    lambda work, items: run_on_ray(work, items, in_flight),
                    floors=floors,
                    selection=selection,
                    resume=args.resume,
                    seconds=args.seconds,
                    tick=tick,
                )
            except WalkMapError as exc:
                raise CliError(str(exc)) from exc
            except KeyboardInterrupt:
                bar.close()
                print(
                    f"stopped; the walks so far are logged to run {trial.run_id}. Go on with: "
                    f"linkevo walkmap {args.ref} --resume",
                    file=sys.stderr,
                )
                return 130
            finally:
                bar.close()
            print(_summary(trial, frame))
    finally:
        signal.signal(signal.SIGTERM, previous)
        if started:
            ray.shutdown()
    return 0


def _interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


def _summary(trial, frame) -> str:
    """One line per floor: cells walked, how many break, the furthest walker."""
    lines = [f"{trial.trial_key} (run {trial.run_id}): {layout.WALK_MAP}, {layout.WALK_MAP_PNG}"]
    for floor, part in frame.groupby("floor"):
        walked = part[part["status"] == "walked"]
        sound = walked[~walked["breaks"]]
        best = sound.sort_values("mean_distance_cm", ascending=False).head(1)
        furthest = (
            f"furthest: cell {int(best['cell'].iloc[0])}, {best['mean_distance_cm'].iloc[0]:.1f} cm"
            if len(best)
            else "none walks"
        )
        others = part[part["status"] != "walked"]["status"].value_counts()
        skipped = "".join(f", {n} {status}" for status, n in others.items())
        lines.append(
            f"  {floor}: {len(walked)} walked, {len(walked) - len(sound)} break{skipped}; "
            f"{furthest}"
        )
    return "\n".join(lines)
