"""Provides `linkevo hexapod`: walk the robot, run field trials (real, or simulated in 3-D),
print the study's Table I."""

from __future__ import annotations

import argparse
import logging
import math
import signal
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from linkevo.orchestrator.cli import CliError

if TYPE_CHECKING:
    from linkevo.hardware.config import RobotConfig

DEFAULT_CONFIG = "configs/hexapod.toml"
"""The robot config when `--config` is not given: the one linkevo ships (`linkevo.configs`)."""
_TRACKING_HELP = "MLflow tracking URI (default: MLFLOW_TRACKING_URI, else runs/mlflow.db)"


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the `hexapod` subcommand group (walk, trial, simulate, study, table)."""
    from linkevo.orchestrator.commands import hexapod_simulate

    parser = subparsers.add_parser(
        "hexapod",
        help="walk the MX-28 hexapod, run field trials, print the field-trial table",
        description="Drives the study's hexapod (six Dynamixel MX-28AT, Protocol 2.0).",
    )
    sub = parser.add_subparsers(dest="hexapod_command", required=True, metavar="ACTION")

    walk = sub.add_parser("walk", help="walk for a fixed time with the phase-locked tripod gait")
    config_option(walk)
    walk.add_argument(
        "--simulate",
        nargs="?",
        const="bus",
        default=None,
        help="run against the built-in bus emulator on a pty: 'bus' (the default when given; "
        "the motors turn as commanded) or 'physics' (the motors are the cranks of the robot "
        "simulated in MuJoCo, walking --linkage on --floor, in real time)",
    )
    walk.add_argument(
        "--linkage", default=None, help="with --simulate physics: RUN_ID[:CELL] or FILE.json"
    )
    walk.add_argument("--floor", default="flat", help="with --simulate physics: flat or carpet")
    walk.add_argument("--seconds", type=float, required=True, help="walking time in seconds")
    walk.add_argument("--telemetry", type=Path, default=None, help="CSV file, one row per tick")
    walk.set_defaults(func=walk_handler)

    trial = sub.add_parser("trial", help="walk an evolved linkage's robot and log the distances")
    _robot_options(trial)
    trial.add_argument("--linkage", required=True, help="source trial run: RUN_ID or RUN_ID:CELL")
    trial.add_argument("--floor", required=True, help="floor name, e.g. flat or carpet")
    trial.add_argument("--robot", default="first", help="first or modified")
    trial.add_argument("--repeats", type=int, default=5, help="walks on this floor")
    trial.add_argument("--seconds", type=float, default=10.0, help="seconds per walk")
    trial.add_argument(
        "--distance-cm",
        type=float,
        nargs="+",
        default=None,
        metavar="D",
        help="measured distances, one per repeat (default: asked on stdin after each walk)",
    )
    trial.add_argument("--tracking-uri", default=None, help=_TRACKING_HELP)
    trial.set_defaults(func=trial_handler)

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
    simulate.add_argument("--floor", required=True, help="flat or carpet")
    simulate.add_argument("--seconds", type=float, default=10.0, help="seconds per walk")
    simulate.add_argument("--repeats", type=int, default=5, help="walks on this floor")
    simulate.add_argument("--robot", default="first", help="first or modified (the table's row)")
    simulate.add_argument(
        "--model",
        default="lean",
        help="lean (legs reduced to what meets the floor; the default) or full (every beam a "
        "body; slower, for pictures)",
    )
    simulate.add_argument("--seed", type=int, default=0, help="seeds the start's perturbation")
    simulate.add_argument("--json", action="store_true", help="print one JSON object")
    simulate.add_argument(
        "--out",
        type=Path,
        default=None,
        help="write the first walk's pictures here (walk.gif, walk.png, path.png, contacts.png)",
    )
    simulate.add_argument("--no-log", action="store_true", help="do not log to MLflow")
    config_option(simulate)
    simulate.add_argument("--experiment", default="linkevo", help="experiment for a FILE.json")
    simulate.add_argument("--tracking-uri", default=None, help=_TRACKING_HELP)
    simulate.set_defaults(func=hexapod_simulate.simulate_handler)

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
    study.add_argument("--seconds", type=float, default=10.0, help="seconds per walk")
    study.add_argument("--repeats", type=int, default=5, help="walks per robot and floor")
    study.add_argument("--out", type=Path, default=None, help="write the table here as CSV")
    study.add_argument("--model", default="lean", help="lean (the default) or full")
    config_option(study)
    study.add_argument("--experiment", default="linkevo", help="MLflow experiment name")
    study.add_argument("--tracking-uri", default=None, help=_TRACKING_HELP)
    study.set_defaults(func=hexapod_simulate.study_handler)

    table = sub.add_parser("table", help="print mean distances as in the study's Table I")
    table.add_argument("--tracking-uri", default=None, help=_TRACKING_HELP)
    table.add_argument("--experiment", default="linkevo", help="MLflow experiment name")
    table.add_argument(
        "--simulated",
        action="store_true",
        help="show the emulator's dry runs (walked with --simulate) instead of the real trials",
    )
    table.set_defaults(func=table_handler)


def config_option(parser: argparse.ArgumentParser) -> None:
    """Adds `--config`: the robot's TOML (default: the one linkevo ships)."""
    parser.add_argument(
        "--config",
        type=Path,
        default=None,
        help=f"robot TOML (default: the shipped {DEFAULT_CONFIG})",
    )


def _robot_options(parser: argparse.ArgumentParser) -> None:
    config_option(parser)
    parser.add_argument(
        "--simulate", action="store_true", help="run against the built-in bus emulator on a pty"
    )


def load_robot(args: argparse.Namespace) -> RobotConfig:
    from linkevo.hardware.config import load_config
    from linkevo.hardware.errors import ConfigError

    if not math.isfinite(args.seconds) or args.seconds <= 0:
        raise CliError(f"--seconds {args.seconds}: allowed a positive number of seconds")
    from linkevo.configs import shipped

    try:
        return load_config(args.config or shipped("hexapod.toml"))
    except ConfigError as exc:
        raise CliError(str(exc)) from exc


def _exit_code(signal_name: str) -> int:
    return 128 + int(getattr(signal, signal_name))


def show_motor_stops() -> None:
    """Prints on stderr each motor's stop as the hexapod reads it back (Goal Velocity 0,
    torque off, or what failed): one line per motor when a walk ends, however it ends
    (`hexapod walk` and each repeat of `hexapod trial`)."""
    log = logging.getLogger("linkevo.hardware.hexapod")
    log.setLevel(logging.INFO)
    log.propagate = False
    if not any(isinstance(h, _Stderr) for h in log.handlers):
        log.addHandler(_Stderr())


class _Stderr(logging.Handler):
    """Writes a record's message to the current `sys.stderr`."""

    def emit(self, record: logging.LogRecord) -> None:
        print(record.getMessage(), file=sys.stderr)


def walk_handler(args: argparse.Namespace) -> int:
    """Walks once and prints the achieved tick rate."""
    from linkevo.hardware.errors import HardwareError, ShutdownIncomplete, StopRequested
    from linkevo.hardware.session import run_walk

    config = load_robot(args)
    physics = _physics_world(args, config)
    show_motor_stops()
    start = None if physics is None else physics.body()
    try:
        result = run_walk(
            config,
            args.seconds,
            telemetry=args.telemetry,
            simulate=args.simulate is not None,
            physics=physics,
        )
    except ShutdownIncomplete as exc:
        ended = f" after: {exc.__cause__}" if exc.__cause__ is not None else ""
        print(f"linkevo hexapod walk: {exc}{ended}; cut the motor power", file=sys.stderr)
        return 1
    except StopRequested as exc:
        print(f"linkevo hexapod walk: {exc}; motors stopped, torque off", file=sys.stderr)
        return _exit_code(exc.signal_name)
    except HardwareError as exc:
        print(f"linkevo hexapod walk: {exc}; motors stopped, torque off", file=sys.stderr)
        return 1
    print(
        f"walked {result.duration_s:.2f} s: {result.ticks} ticks at {result.rate_hz:.1f} Hz "
        f"(target {config.gait.rate_hz:g} Hz), skipped {result.skipped_ticks}, "
        f"missed reads {result.missed_reads}, reboots {result.reboots}, "
        f"watchdog re-arms {result.watchdog_rearms}, "
        f"max phase error {math.degrees(result.max_phase_error_rad):.1f}°"
    )
    if physics is not None:
        moved = (physics.body() - start) * 100
        print(
            f"the simulated robot moved {moved[0]:.1f} cm along its length, "
            f"{moved[1]:.1f} cm across"
        )
    if args.telemetry is not None:
        print(f"telemetry: {args.telemetry}")
    return 0


def _physics_world(args: argparse.Namespace, config):
    """Returns the simulated robot `--simulate physics` drives, or None for the plain
    emulator or the real robot.

    Raises:
        CliError: a bad --simulate, --floor or --linkage, before anything starts.
    """
    if args.simulate not in (None, "bus", "physics"):
        raise CliError(f"--simulate {args.simulate!r}: allowed bus, physics")
    if args.simulate != "physics":
        if args.linkage is not None:
            raise CliError("--linkage is used with --simulate physics only")
        return None
    from linkevo.hardware.physics_bus import PhysicsWorld
    from linkevo.orchestrator.commands.hexapod_simulate import simulation_source
    from linkevo.sim.leg import LegError, leg_from_genome
    from linkevo.sim.linkage_doc import from_document
    from linkevo.sim.robot import FLOORS

    if args.floor not in FLOORS:
        raise CliError(f"--floor {args.floor!r}: allowed {', '.join(FLOORS)}")
    if args.linkage is None:
        raise CliError("--simulate physics needs --linkage RUN_ID[:CELL] or FILE.json")
    args.no_log, args.experiment, args.tracking_uri = True, "linkevo", None
    _, source = simulation_source(args)
    try:
        leg = leg_from_genome(*from_document(source.document))
        return PhysicsWorld(config, leg, FLOORS[args.floor])
    except (LegError, ValueError) as exc:
        raise CliError(str(exc)) from exc


def _ask_distance(repeat: int) -> float:
    while True:
        try:
            text = input(f"distance walked in repeat {repeat} (cm): ")
        except EOFError as exc:
            raise CliError(f"no distance given for repeat {repeat} (stdin closed)") from exc
        try:
            value = float(text)
        except ValueError:
            print(f"{text!r} is not a number; enter the distance in cm", file=sys.stderr)
            continue
        if math.isfinite(value) and value >= 0:
            return value
        print(f"{value} cm: allowed a finite value >= 0", file=sys.stderr)


def trial_handler(args: argparse.Namespace) -> int:
    """Walks the repeats, records the distances and logs a field-trial MLflow run."""
    from linkevo.hardware.errors import HardwareError, StopRequested
    from linkevo.hardware.field_trial import ROBOTS, log_field_trial, walk_repeats
    from linkevo.workers.store.linkages import LinkageRef, load_source
    from linkevo.workers.store.runs import RunStore
    from linkevo.workers.store.tracking import resolve_tracking_uri

    if args.robot not in ROBOTS:
        raise CliError(f"--robot {args.robot!r}: allowed {', '.join(ROBOTS)}")
    if args.repeats < 1:
        raise CliError(f"--repeats {args.repeats}: allowed an integer >= 1")
    if not args.floor.strip():
        raise CliError("--floor '': allowed a non-empty floor name")
    distances = args.distance_cm
    if distances is not None:
        if len(distances) != args.repeats:
            raise CliError(
                f"--distance-cm has {len(distances)} value(s); allowed exactly --repeats "
                f"= {args.repeats}"
            )
        bad = [d for d in distances if not math.isfinite(d) or d < 0]
        if bad:
            raise CliError(f"--distance-cm {bad}: allowed finite values >= 0")
    config = load_robot(args)
    show_motor_stops()
    uri = resolve_tracking_uri(args.tracking_uri)
    source = load_source(RunStore.open(uri), LinkageRef.parse(args.linkage))

    def measure(repeat: int) -> float:
        return distances[repeat - 1] if distances is not None else _ask_distance(repeat)

    with tempfile.TemporaryDirectory() as tmp:
        try:
            measured, files = walk_repeats(
                config,
                repeats=args.repeats,
                seconds=args.seconds,
                measure=measure,
                telemetry_dir=Path(tmp),
                simulate=args.simulate,
            )
        except StopRequested as exc:
            print(f"linkevo hexapod trial: {exc}; nothing logged", file=sys.stderr)
            return _exit_code(exc.signal_name)
        except HardwareError as exc:
            print(f"linkevo hexapod trial: {exc}; nothing logged", file=sys.stderr)
            return 1
        params = {
            "seconds": str(args.seconds),
            "repeats": str(args.repeats),
            "config": str(args.config or DEFAULT_CONFIG),
            "simulated": str(args.simulate),
        }
        run_id = log_field_trial(
            uri,
            source,
            robot=args.robot,
            floor=args.floor,
            distances=measured,
            params=params,
            telemetry=files,
        )
    mean = sum(measured) / len(measured)
    print(
        f"field trial {run_id}: {source.approach}, {args.robot} robot, floor {args.floor}: "
        f"mean {mean:.1f} cm over {len(measured)} walk(s)"
    )
    return 0


def table_handler(args: argparse.Namespace) -> int:
    """Prints the field-trial means in the study's Table I layout."""
    from linkevo.hardware.field_trial import FieldTrialError, trial_table
    from linkevo.workers.store.tracking import require_store, resolve_tracking_uri

    uri = require_store(resolve_tracking_uri(args.tracking_uri))
    try:
        table = trial_table(uri, args.experiment, simulated=args.simulated)
    except FieldTrialError as exc:
        raise CliError(str(exc)) from exc
    kind = "emulator dry-run" if table.simulated else "real"
    other = "real" if table.simulated else "emulator dry-run"
    if not table.means and not table.predicted:
        print(f"no {kind} field trials logged in experiment {args.experiment!r}")
    elif table.predicted:
        print(f"Real field trials / predicted by the 3-D simulation:\n{table.format()}")
    else:
        print(f"{kind.capitalize()} field trials:\n{table.format()}")
    if table.left_out:
        hint = "" if table.simulated else " (--simulated shows them)"
        print(f"{table.left_out} {other} field-trial run(s) left out{hint}")
    return 0
