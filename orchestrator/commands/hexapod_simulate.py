"""Provides `linkevo hexapod simulate` (simulated field trials in 3-D) and `linkevo hexapod
study` (the study's Table I, predicted)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from linkevo.orchestrator.cli import CliError
from linkevo.orchestrator.commands.hexapod import load_robot

MAX_SIM_SECONDS = 600.0
MAX_REPEATS = 100


def simulate_handler(args: argparse.Namespace) -> int:
    """Walks the linkage's robot in 3-D physics and prints (and logs) the predicted trial."""
    import json

    from linkevo.hardware.field_trial import ROBOTS
    from linkevo.orchestrator.simulate import log_simulated, simulate_source, write_pictures
    from linkevo.sim.robot import FLOORS
    from linkevo.sim.walking import MODELS

    if args.floor not in FLOORS:
        raise CliError(f"--floor {args.floor!r}: allowed {', '.join(FLOORS)}")
    if not math.isfinite(args.seconds) or not 0 < args.seconds <= MAX_SIM_SECONDS:
        raise CliError(f"--seconds {args.seconds}: allowed a number in (0, {MAX_SIM_SECONDS:g}]")
    if not 1 <= args.repeats <= MAX_REPEATS:
        raise CliError(f"--repeats {args.repeats}: allowed an integer in [1, {MAX_REPEATS}]")
    if args.model not in MODELS:
        raise CliError(f"--model {args.model!r}: allowed {', '.join(MODELS)}")
    if args.robot not in ROBOTS:
        raise CliError(f"--robot {args.robot!r}: allowed {', '.join(ROBOTS)}")
    if args.seed < 0:
        raise CliError(f"--seed {args.seed}: allowed an integer >= 0")
    config = load_robot(args)
    uri, source = simulation_source(args)
    try:
        result, walks = simulate_source(
            source,
            args.floor,
            config=config,
            seconds=args.seconds,
            repeats=args.repeats,
            seed=args.seed,
            model=args.model,
        )
    except ValueError as exc:
        raise CliError(str(exc)) from exc
    pictures = []
    if args.out is not None and walks:
        title = f"{source.approach} {args.robot} robot, {args.floor} floor, repeat 1"
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
    from linkevo.orchestrator.simulate import document_source
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
            f"{result['pin_force_p99_n']} N; loop closure within {result['loop_error_max_mm']} mm"
        )
    if result.get("beyond_bound"):
        lines.append(
            "  beyond the no-slip bound, which holds for a level body: the robot rocks "
            f"(pitch up to {result['max_pitch_deg']}°) and its feet slip; trust the distance less"
        )
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

    if not math.isfinite(args.seconds) or not 0 < args.seconds <= MAX_SIM_SECONDS:
        raise CliError(f"--seconds {args.seconds}: allowed a number in (0, {MAX_SIM_SECONDS:g}]")
    if not 1 <= args.repeats <= MAX_REPEATS:
        raise CliError(f"--repeats {args.repeats}: allowed an integer in [1, {MAX_REPEATS}]")
    if args.out is not None and args.out.suffix != ".csv":
        raise CliError(f"--out {args.out}: allowed a .csv file")
    from linkevo.sim.walking import MODELS

    if args.model not in MODELS:
        raise CliError(f"--model {args.model!r}: allowed {', '.join(MODELS)}")
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
