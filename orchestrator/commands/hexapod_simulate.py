"""Provides `linkevo hexapod simulate` (simulated field trials in 3-D) and `linkevo hexapod
study` (the study's Table I, predicted)."""

from __future__ import annotations

import argparse
from pathlib import Path

from linkevo.orchestrator.cli import CliError
from linkevo.orchestrator.commands import options
from linkevo.orchestrator.commands.hexapod import load_robot


def register(sub: argparse._SubParsersAction) -> None:
    """Adds `hexapod simulate` and `hexapod study` to the hexapod group."""
    simulate = sub.add_parser(
        "simulate",
        help="walk a linkage's robot in 3-D physics (MuJoCo): Table I's protocol, predicted",
        description=(
            "Walks the study's hexapod with six copies of the linkage (its LEGO build) in "
            "MuJoCo, with the gait of the robot config, and reports the distance walked along "
            "the starting heading per repeat, whether the robot breaks and why, and what a "
            "builder needs to trust the number (docs/walking.md). Logged as a field trial "
            "marked simulated, so `linkevo hexapod table` shows it beside the real ones."
        ),
    )
    simulate.add_argument(
        "--linkage", required=True, help="RUN_ID, RUN_ID:CELL or a linkage document FILE.json"
    )
    options.floor(simulate, required=True)
    options.seconds(simulate)
    options.repeats(simulate)
    options.robot(simulate)
    options.robot_model(simulate)
    simulate.add_argument(
        "--seed", type=options.count(0, 2**31), default=0, help="seeds the start's perturbation"
    )
    simulate.add_argument("--json", action="store_true", help="print one JSON object")
    simulate.add_argument(
        "--out",
        type=Path,
        default=None,
        help="write the first walk's pictures into this folder (walk.gif, walk.png, path.png, "
        "contacts.png)",
    )
    simulate.add_argument("--no-log", action="store_true", help="do not log to MLflow")
    options.robot_config(simulate)
    options.store(simulate)
    simulate.set_defaults(func=simulate_handler)

    study = sub.add_parser(
        "study",
        help="repeat the study's prototyping (Table I) on the simulated robot for a grid",
        description=(
            "For each MAP-Elites approach with F_p: the first robot (the best linkage of the "
            "approach's best trial) and a modified robot chosen from its 5 × 5 downsampled "
            "map, each walked on both floors in 3-D physics and logged as simulated field "
            "trials (docs/walking.md)."
        ),
    )
    study.add_argument("grid_id", help="the grid (its id, as `linkevo report` shows it)")
    options.seconds(study)
    options.repeats(study, "walks per robot and floor")
    study.add_argument("--out", type=Path, default=None, help="write the table here as CSV")
    options.robot_model(study)
    options.robot_config(study)
    options.store(study)
    study.set_defaults(func=study_handler)


def simulate_handler(args: argparse.Namespace) -> int:
    """Walks the linkage's robot in 3-D physics and prints (and logs) the predicted trial."""
    import json

    from linkevo.orchestrator.simulated_trials import (
        log_simulated,
        simulate_source,
        write_pictures,
    )

    if args.out is not None and args.out.exists() and not args.out.is_dir():
        raise CliError(f"--out {str(args.out)!r} is a file; allowed: a folder (new or existing)")
    config = load_robot(args)
    uri, source = simulation_source(args)
    result, walks = simulate_source(
        source,
        args.floor,
        config=config,
        seconds=args.seconds,
        repeats=args.repeats,
        seed=args.seed,
        model=args.model,
    )
    pictures = []
    if args.out is not None and walks:
        what = (f"{source.approach} {args.robot} robot" if source.approach != "unknown"
                else Path(args.linkage).name)  # fmt: skip
        title = f"{what}, {args.floor} floor, repeat 1"
        pictures = write_pictures(walks[0], args.out, title)
    if not args.no_log:
        result["run_id"] = log_simulated(uri, source, args.robot, result, args.seed, pictures)
    if args.json:
        print(json.dumps(result))
        return 0
    print(_simulation_text(source, args.robot, result))
    return 0


def simulation_source(args: argparse.Namespace):
    """Returns (tracking URI, the source linkage) of `--linkage`."""
    from linkevo.orchestrator.simulated_trials import document_source
    from linkevo.workers.store.linkages import LinkageRef, load_source
    from linkevo.workers.store.runs import RunStore
    from linkevo.workers.store.tracking import ensure_experiment, resolve_tracking_uri

    uri = resolve_tracking_uri(args.tracking_uri)
    path = Path(args.linkage)
    if args.linkage.endswith(".json"):
        if not path.is_file():
            raise CliError(f"--linkage {args.linkage}: no such file")
        experiment_id = "" if args.no_log else ensure_experiment(uri, args.experiment)
        return uri, document_source(path, experiment_id)
    ref = LinkageRef.parse(args.linkage)
    return uri, load_source(RunStore.open(uri, args.experiment), ref)


def _simulation_text(source, robot: str, result: dict) -> str:
    """The simulated trial as a few lines a builder reads."""
    head = f"{source.approach} {robot} robot on the {result['floor']} floor"
    lines = [
        f"{head} ({result['seconds']:g} s per walk, {result.get('leg', 'no leg')}, "
        f"{result.get('model', 'lean')} model):"
    ]
    if result["distance_cm"]:
        walked = ", ".join("–" if d is None else f"{d:.1f}" for d in result["distance_cm"])
        lines.append(
            f"  distance {walked} cm; mean {result['mean_distance_cm']} cm "
            f"(no-slip bound {result['bound_cm']} cm)"
        )
        lines.append(
            f"  body {result['body_height_cm']} cm high, pitch ≤ {result['max_pitch_deg']}°, "
            f"roll ≤ {result['max_roll_deg']}°, foot slip {result['foot_slip_mm_s']} mm/s"
        )
        lines.append(
            f"  motor torque {result['torque_p95_of_stall']:.0%} of stall (95th pct), "
            f"peak {result['torque_max_of_stall']:.0%}; pin force p50/p95/p99 "
            f"{result['pin_force_p50_n']}/{result['pin_force_p95_n']}/"
            f"{result['pin_force_p99_n']} N; loop closure within {result['loop_error_max_mm']} "
            f"mm, feet within {result['foot_deviation_max_mm']} mm of their path"
        )
    for caveat in result.get("caveats", []):
        lines.append(f"  caveat: {caveat}")
    verdict = f"BREAKS: {result['reason']}" if result["breaks"] else "walks"
    lines.append(f"  {verdict}")
    if "run_id" in result:
        lines.append(f"  logged as field trial {result['run_id']} (linkevo hexapod table)")
    return "\n".join(lines)


def study_handler(args: argparse.Namespace) -> int:
    """Predicts the study's Table I for a grid and prints it (and writes it with --out)."""
    from linkevo.orchestrator.walk_study import predict_table_one
    from linkevo.workers.store.artifacts import write_text_atomic
    from linkevo.workers.store.runs import RunStore

    if args.out is not None and args.out.suffix != ".csv":
        raise CliError(f"--out {args.out}: allowed a .csv file")
    config = load_robot(args)
    table = predict_table_one(
        RunStore.open(args.tracking_uri, args.experiment),
        args.grid_id,
        config=config,
        seconds=args.seconds,
        repeats=args.repeats,
        model=args.model,
    )
    if args.out is not None:
        write_text_atomic(args.out, table.to_csv(index=False))
        print(f"table: {args.out}")
    return 0
