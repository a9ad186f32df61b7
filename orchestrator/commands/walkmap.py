"""Provides `linkevo walkmap`: every chosen cell of a repertoire (or of each repertoire of
a grid) walked on the simulated robot, fanned out over Ray."""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from linkevo.orchestrator.cli import interrupted_code
from linkevo.orchestrator.commands import options
from linkevo.orchestrator.commands.hexapod import load_robot
from linkevo.sim.robot.hexapod import FLOORS
from linkevo.sim.robot.walk_rows import Status
from linkevo.workers.store import run_layout as layout

BOTH = "both"


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the `walkmap` subcommand."""
    parser = subparsers.add_parser(
        "walkmap",
        help="walk every chosen cell of a repertoire on the simulated robot (a walk map)",
        description=(
            "Walks the robot of every chosen cell of REF's repertoire (a trial's RUN_ID, or "
            "each repertoire trial of a GRID_ID) once for 10 s on each floor in 3-D physics "
            "(docs/walking.md), fanned out over Ray (the legs built, then each distinct leg "
            "walked once), and logs the walk map to the trial's run: walkmap.parquet (a row "
            "per cell and floor: distance, breaks, reason) and walkmap.png. `linkevo "
            "explore` then colours the map by distance and `linkevo pull` prints a cell's. "
            "One walk map per run is made at a time; Ctrl-C keeps what was walked and "
            "prints the line that completes the map."
        ),
    )
    parser.add_argument("ref", help="a repertoire trial's RUN_ID, or a GRID_ID")
    parser.add_argument(
        "--floor", default=BOTH, choices=(*FLOORS, BOTH), help="the floor(s) to walk on"
    )
    parser.add_argument(
        "--cells",
        default="buildable",
        help="buildable (the cells that pass the 2-D physical checks, walked as their LEGO "
        "build; the default), best:K (the K lowest-loss of those) or all (every cell, as "
        "evolved where no LEGO build turns)",
    )
    options.seconds(parser, "seconds per walk")
    again = parser.add_mutually_exclusive_group()
    again.add_argument(
        "--resume", action="store_true", help="walk only the cells the run's walk map lacks"
    )
    again.add_argument(
        "--restart",
        action="store_true",
        help="walk the map anew, replacing the one the run has (a damaged one, say)",
    )
    options.robot_config(parser)
    options.ray_address(parser)
    options.store(parser)
    parser.set_defaults(func=handle)


def handle(args: argparse.Namespace) -> int:
    """Handles `linkevo walkmap`."""
    from tqdm import tqdm

    from linkevo.orchestrator.repertoire_walks import (
        Selection,
        check_before_walking,
        run_on_ray,
        top_walkers,
        walk_map,
    )
    from linkevo.workers.store.runs import RunStore

    selection = Selection.parse(args.cells)
    floors = tuple(FLOORS) if args.floor == BOTH else (args.floor,)
    robot = load_robot(args).robot()
    store = RunStore.open(args.tracking_uri, args.experiment)
    trials = store.repertoires(args.ref).trials
    for trial in trials:  # before Ray starts or anything is walked
        check_before_walking(store, trial, args.resume, args.restart, robot)

    import ray

    from linkevo.orchestrator.ray_connection import connect_ray
    from linkevo.orchestrator.reservation import Cluster

    started = connect_ray(args.address, Cluster.this_machine())
    in_flight = 2 * int(Cluster.of_ray().total_cpus)
    try:
        for trial in trials:
            bars: dict[str, tqdm] = {}

            def tick(step: str, done: int, total: int, bars=bars, key=trial.trial_key) -> None:
                if step not in bars:  # a new step: its own bar, count and rate
                    for bar in bars.values():
                        bar.close()
                    unit = "cell" if step == "building legs" else "walk"
                    bars[step] = tqdm(
                        desc=f"walkmap {key}: {step}", unit=unit, total=total, file=sys.stderr
                    )
                bar = bars[step]
                bar.total = total
                bar.update(done - bar.n)

            try:
                result = walk_map(
                    store,
                    trial,
                    lambda work, items: run_on_ray(work, items, in_flight),
                    floors=floors,
                    selection=selection,
                    resume=args.resume,
                    restart=args.restart,
                    seconds=args.seconds,
                    robot=robot,
                    tick=tick,
                )
            except KeyboardInterrupt as exc:
                for bar in bars.values():
                    bar.close()
                print(
                    f"stopped; the walks so far are logged to run {trial.run_id}. Complete "
                    f"the map with:  {_resume_command(args)}",
                    file=sys.stderr,
                )
                return interrupted_code(exc)
            finally:
                for bar in bars.values():
                    bar.close()
            if not result.walked:
                print(f"{trial.trial_key} (run {trial.run_id}): the walk map is complete")
            print(summary(trial, result.frame))
            with tempfile.TemporaryDirectory() as tmp:
                repertoire = store.repertoire(trial.run_id, Path(tmp))
            for line in walker_lines(top_walkers(result.frame, repertoire, trial.mode)):
                print(line)
    finally:
        if started:
            ray.shutdown()
    return 0


def _resume_command(args: argparse.Namespace) -> str:
    """Returns the command line that completes the walk map: every option as given, with
    --resume."""
    given = [
        ("--floor", args.floor, BOTH),
        ("--cells", args.cells, "buildable"),
        ("--seconds", args.seconds, options.WALK_SECONDS),
        ("--config", args.config, None),
        ("--address", args.address, None),
        ("--experiment", args.experiment, options.DEFAULT_EXPERIMENT),
        ("--tracking-uri", args.tracking_uri, None),
    ]
    words = ["walkmap", args.ref]
    for flag, value, default in given:
        if value != default:
            words += [flag, f"{value:g}" if isinstance(value, float) else str(value)]
    return options.linkevo_command(*words, "--resume")


def summary(trial, frame) -> str:
    """One line per floor: cells walked, how many of them walk (and how many of those go
    beyond the level-body bound) and break (and how many of those are frail legs), the
    cells not walked, the furthest walker."""
    lines = [f"{trial.trial_key} (run {trial.run_id}): {layout.WALK_MAP}, {layout.WALK_MAP_PNG}"]
    for floor, part in frame.groupby("floor"):
        walked = part[part["status"] == Status.WALKED]
        sound = walked[~walked["breaks"].astype(bool)]
        best = sound.sort_values("mean_distance_cm", ascending=False).head(1)
        furthest = (
            f"furthest: cell {int(best['cell'].iloc[0])}, {best['mean_distance_cm'].iloc[0]:.1f} cm"
            if len(best)
            else "none walks"
        )
        others = part[part["status"] != Status.WALKED]["status"].value_counts()
        skipped = "".join(f", {n} {status}" for status, n in others.items())
        beyond = int((sound["mean_distance_cm"] > sound["bound_cm"]).sum())
        frail = int(walked["reason"].fillna("").str.contains("frail:").sum())
        lines.append(
            f"  {floor}: {len(walked)} cells walked: {len(sound)} walk ({beyond} beyond the "
            f"level-body bound), {len(walked) - len(sound)} break ({frail} frail){skipped}; "
            f"{furthest}"
        )
    return "\n".join(lines)


def walker_lines(walkers: list[dict]) -> list[str]:
    """The walk map's top walkers (`orchestrator.repertoire_walks.top_walkers`), a line
    each, with what a builder should doubt."""
    lines = ["  top walkers (by the worse floor, cm per 10 s credited):"] if walkers else []
    for w in walkers:
        floors = ", ".join(f"{f} {cm:.1f}" for f, cm in w["credited_cm"].items())
        shape = w["shape"]
        leg = (
            f"; a leg {shape['size_cm'][0]:.0f} x {shape['size_cm'][1]:.0f} cm, stroke "
            f"{shape['stroke_cm']:.0f} cm, crank share {shape['crank_share']:.2f}"
            if shape
            else ""
        )
        beyond = w["beyond_bound_share"]
        doubt = f"; {beyond:.0%} beyond the level-body bound" if beyond > 0 else ""
        doubt += "; SLIDES: its feet slip at over half the body's speed" if w["slides"] else ""
        lines.append(f"    cell {w['cell']}: {floors}{leg}{doubt}")
    return lines
