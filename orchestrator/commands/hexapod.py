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
from linkevo.orchestrator.commands import options

if TYPE_CHECKING:
    from linkevo.hardware.config import RobotConfig


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the `hexapod` subcommand group (walk, trial, simulate, study, calibrate, table)."""
    from linkevo.orchestrator.commands import hexapod_calibrate, hexapod_simulate

    parser = subparsers.add_parser(
        "hexapod",
        help="walk the MX-28 hexapod, run field trials, print the field-trial table",
        description="Drives the study's hexapod (six Dynamixel MX-28AT, Protocol 2.0).",
    )
    sub = parser.add_subparsers(dest="hexapod_command", required=True, metavar="ACTION")
    _register_walk(sub)
    _register_trial(sub)
    hexapod_simulate.register(sub)
    hexapod_calibrate.register(sub)
    _register_table(sub)


def _register_walk(sub: argparse._SubParsersAction) -> None:
    walk = sub.add_parser("walk", help="walk for a fixed time with the phase-locked tripod gait")
    options.robot_config(walk)
    walk.add_argument(
        "--emulate",
        nargs="?",
        const="bus",
        default=None,
        choices=EMULATORS,
        help="run against the built-in bus emulator on a pty: 'bus' (the default when given; "
        "the motors turn as commanded) or 'physics' (the motors are the cranks of the robot "
        "simulated in MuJoCo, walking --linkage on --floor, in real time)",
    )
    walk.add_argument(
        "--linkage", default=None, help="with --emulate physics: RUN_ID[:CELL] or FILE.json"
    )
    options.floor(walk)
    options.seconds(walk, "walking time in seconds", required=True)
    walk.add_argument("--telemetry", type=Path, default=None, help="CSV file, one row per tick")
    walk.set_defaults(func=walk_handler)


def _register_trial(sub: argparse._SubParsersAction) -> None:
    trial = sub.add_parser("trial", help="walk an evolved linkage's robot and log the distances")
    options.robot_config(trial)
    trial.add_argument(
        "--emulate", action="store_true", help="run against the built-in bus emulator on a pty"
    )
    trial.add_argument("--linkage", required=True, help="source trial run: RUN_ID or RUN_ID:CELL")
    trial.add_argument("--floor", required=True, type=floor_name, help="the floor's name")
    options.robot(trial)
    options.repeats(trial)
    options.seconds(trial, "seconds per walk")
    trial.add_argument(
        "--distance-cm",
        type=float,
        nargs="+",
        default=None,
        metavar="D",
        help="measured distances, one per repeat (default: asked on stdin after each walk)",
    )
    options.store(trial)
    trial.set_defaults(func=trial_handler)


def _register_table(sub: argparse._SubParsersAction) -> None:
    table = sub.add_parser("table", help="print mean distances as in the study's Table I")
    options.store(table)
    table.add_argument(
        "--emulated",
        action="store_true",
        help="show the emulator's dry runs (walked with --emulate) instead of the real trials",
    )
    table.set_defaults(func=table_handler)


EMULATORS = ("bus", "physics")
"""What `hexapod walk --emulate` runs against: the bus emulator's motors alone, or as the
cranks of the robot simulated in MuJoCo."""


def floor_name(text: str) -> str:
    """Returns a real floor's name (free text: a robot walks on any floor), not empty."""
    if not text.strip():
        raise argparse.ArgumentTypeError("'' is not allowed: a non-empty floor name")
    return text


def load_robot(args: argparse.Namespace) -> RobotConfig:
    """Returns the robot config `--config` names (default: the shipped one)."""
    from linkevo.configs import shipped
    from linkevo.hardware.config import load_config

    return load_config(args.config or shipped("hexapod.toml"))


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
            simulate=args.emulate is not None,
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
    """Returns the simulated robot `--emulate physics` drives, or None for the plain
    emulator or the real robot.

    Raises:
        CliError: a --linkage without --emulate physics, or none with it.
        LinkevoError: a linkage that cannot be walked, before anything starts.
    """
    if args.emulate != "physics":
        if args.linkage is not None:
            raise CliError("--linkage is used with --emulate physics only")
        return None
    from linkevo.hardware.physics_bus import PhysicsWorld
    from linkevo.orchestrator.commands.hexapod_simulate import simulation_source
    from linkevo.sim.linkage.linkage_doc import from_document
    from linkevo.sim.robot.hexapod import FLOORS
    from linkevo.sim.robot.leg import leg_from_genome

    if args.linkage is None:
        raise CliError("--emulate physics needs --linkage RUN_ID[:CELL] or FILE.json")
    args.no_log, args.experiment, args.tracking_uri = True, options.DEFAULT_EXPERIMENT, None
    _, source = simulation_source(args)
    leg = leg_from_genome(*from_document(source.document))
    return PhysicsWorld(config, leg, FLOORS[args.floor])


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
    from linkevo.hardware.field_trial import log_field_trial, walk_repeats
    from linkevo.workers.store import run_layout as layout
    from linkevo.workers.store.linkages import LinkageRef, load_source
    from linkevo.workers.store.runs import RunStore
    from linkevo.workers.store.tracking import resolve_tracking_uri

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
                simulate=args.emulate,
            )
        except StopRequested as exc:
            print(f"linkevo hexapod trial: {exc}; nothing logged", file=sys.stderr)
            return _exit_code(exc.signal_name)
        except HardwareError as exc:
            print(f"linkevo hexapod trial: {exc}; nothing logged", file=sys.stderr)
            return 1
        params = {
            layout.SECONDS: str(args.seconds),
            "repeats": str(args.repeats),
            "config": str(args.config or options.ROBOT_CONFIG),
            layout.SIMULATED: str(args.emulate),  # the stored param's name (docs/hardware.md)
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
    from linkevo.hardware.field_trial import trial_table
    from linkevo.workers.store.tracking import require_store, resolve_tracking_uri

    uri = require_store(resolve_tracking_uri(args.tracking_uri))
    table = trial_table(uri, args.experiment, simulated=args.emulated)
    kind = "emulator dry-run" if table.simulated else "real"
    other = "real" if table.simulated else "emulator dry-run"
    if not table.means and not table.predicted:
        print(f"no {kind} field trials logged in experiment {args.experiment!r}")
    elif table.predicted:
        print(f"Real field trials / predicted by the 3-D simulation:\n{table.format()}")
    else:
        print(f"{kind.capitalize()} field trials:\n{table.format()}")
    if table.left_out:
        hint = "" if table.simulated else " (--emulated shows them)"
        print(f"{table.left_out} {other} field-trial run(s) left out{hint}")
    return 0
