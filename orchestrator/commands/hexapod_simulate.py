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
    options.seed(simulate, "seeds the start's perturbation")
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
            "By the paper's protocol, for each MAP-Elites approach with F_p and each of K "
            "trials drawn by a seed: the first robot (the drawn trial's best linkage) and a "
            "modified robot from its 5 × 5 downsampled map (the neighbouring region nearest "
            "the first's path with the change the paper's builders sought; none, 'no "
            "modification possible', where no buildable neighbour has it), each walked on "
            "both floors on both robot models and logged as simulated field trials; then the "
            "paper's prototyping claims judged over the draws (docs/results.md)."
        ),
    )
    study.add_argument("grid_id", help="the grid (its id, as `linkevo report` shows it)")
    study.add_argument(
        "--trials-drawn",
        type=options.count(1, 1000),
        default=10,
        help=(
            "trials drawn per approach (default 10; the paper drew 1): the sign test can say "
            "'reproduced' from 6 draws on; at 10 it does so with a chance of 0.74 when 9 in 10 "
            "draws truly go the claimed way (0.38 at 8 in 10; docs/results.md)"
        ),
    )
    study.add_argument(
        "--draw-seed", type=options.count(0, 2**31), default=0, help="seeds the draw"
    )
    study.add_argument(
        "--first",
        choices=("drawn", "best"),
        default="drawn",
        help="drawn: the drawn trials' best linkages; best: the approach's best trial only",
    )
    study.add_argument(
        "--modified",
        choices=("sought", "walked"),
        default="sought",
        help="sought: the nearest neighbouring path with the builders' change (no walk); "
        "walked: the neighbour that walks furthest on flat",
    )
    options.seconds(study)
    options.repeats(study, "walks per robot, floor and model")
    study.add_argument(
        "--out",
        type=Path,
        default=None,
        help="write table1_predicted.csv and table1_verdicts.csv into this folder",
    )
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

    if args.out is not None:
        options.output_folder(args.out)
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
        what = (
            f"{source.approach} {args.robot} robot"
            if source.approach != "unknown"
            else Path(args.linkage).name
        )
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
    if result.get("spacers"):
        from linkevo.sim.robot.mounting import spacers_text

        lines.append(f"  mounted on spacer layers: {spacers_text(result['spacers'])}")
    frail = result.get("frailty")
    if frail:
        low, mid, high = frail["give_mm"]
        lines.append(
            f"  frailty: {frail['verdict']}; the foot gives {mid} mm ({low}-{high} over the "
            f"ranges of E, section and pin play) under the robot's weight, against a lift of "
            f"{frail['lift_mm']} mm; beams stressed to {frail['stress_mpa'][1]} MPa; pins "
            f"bent out of the plane by {frail['pin_moment_nmm'][1]} N·mm; the motor's axle "
            f"by {frail['axle_moment_nmm'][1]} N·mm ({frail['axle_mm']} mm out)"
        )
        if frail["verdict"] != "sound":
            lines.append(
                f"    {frail['verdict']}: at the ends of the ranges least in its favour, "
                + "; ".join(frail["limits_passed"])
            )
    for caveat in result.get("caveats", []):
        lines.append(f"  caveat: {caveat}")
    verdict = f"BREAKS: {result['reason']}" if result["breaks"] else "walks"
    lines.append(f"  {verdict}")
    if "run_id" in result:
        lines.append(f"  logged as field trial {result['run_id']} (linkevo hexapod table)")
    return "\n".join(lines)


def study_handler(args: argparse.Namespace) -> int:
    """Predicts the study's Table I for a grid, judges the prototyping claims and prints
    them (and writes both tables with --out)."""
    from linkevo.orchestrator.table_one_verdicts import WALK_CM, judge_prototyping
    from linkevo.orchestrator.walk_study import predict_table_one
    from linkevo.workers.store.artifacts import write_text_atomic
    from linkevo.workers.store.runs import RunStore

    if args.out is not None:
        if args.out.suffix == ".csv":
            raise CliError(f"--out {args.out}: allowed a folder (the two tables go into it)")
        options.output_folder(args.out)
    config = load_robot(args)
    table = predict_table_one(
        RunStore.open(args.tracking_uri, args.experiment),
        args.grid_id,
        config=config,
        seconds=args.seconds,
        repeats=args.repeats,
        trials_drawn=args.trials_drawn,
        draw_seed=args.draw_seed,
        first=args.first,
        modified=args.modified,
    )
    verdicts = judge_prototyping(table)
    print(f"\nThe prototyping claims (walks: no break and more than {WALK_CM:g} cm forward):")
    for row in verdicts.itertuples():
        print(f"  {row.claim} ({row.where})")
        print(f"    lean [{row.verdict_lean}] {row.evidence_lean}")
        print(f"    full [{row.verdict_full}] {row.evidence_full}")
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        write_text_atomic(args.out / "table1_predicted.csv", table.to_csv(index=False))
        write_text_atomic(args.out / "table1_verdicts.csv", verdicts.to_csv(index=False))
        print(f"tables: {args.out}/table1_predicted.csv, table1_verdicts.csv")
    return 0
