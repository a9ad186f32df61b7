"""Provides the options several commands share, each declared and checked once: the store
(`--tracking-uri`, `--experiment`), a walk's `--seconds`, `--floor` (from
`sim.robot.hexapod.FLOORS`), Ray's `--address`, the robot's `--config`, a search's `--mode`,
`--seed` and `--target`; and `linkevo_command`, how to run linkevo again as this process
was run (for the lines that resume a command).

A value an option refuses stops the command in argparse, before anything starts, with the
value and what is allowed (exit 2).
"""

from __future__ import annotations

import argparse
import math
import shlex
import sys
from pathlib import Path

from linkevo.sim.robot.hexapod import FLAT, FLOORS, ROBOT_MODELS, WALK_SECONDS
from linkevo.sim.study import MODES, ROBOTS, TARGETS
from linkevo.workers.store.tracking import DEFAULT_EXPERIMENT

MAX_SECONDS = 600.0
"""The longest walk a command takes (ten minutes of simulated walking)."""
MAX_REPEATS = 100
"""The most walks per robot and floor a command takes."""
MAX_SEED = 2**32 - 1
"""The largest seed a command takes (a grid's trial seeds are 32-bit)."""
ROBOT_CONFIG = "configs/hexapod.toml"
"""The robot config when `--config` is not given: the one linkevo ships (`linkevo.configs`)."""

__all__ = [
    "DEFAULT_EXPERIMENT",
    "MAX_SECONDS",
    "ROBOT_CONFIG",
    "WALK_SECONDS",
    "linkevo_command",
]


def tracking_uri(
    parser: argparse.ArgumentParser,
    what: str = "MLflow tracking URI (default: MLFLOW_TRACKING_URI, else runs/mlflow.db)",
) -> None:
    """Adds `--tracking-uri` (checked where the store is opened: `workers.store.tracking`)."""
    parser.add_argument("--tracking-uri", default=None, help=what)


def store(parser: argparse.ArgumentParser) -> None:
    """Adds `--tracking-uri` and `--experiment`."""
    tracking_uri(parser)
    parser.add_argument("--experiment", default=DEFAULT_EXPERIMENT, help="MLflow experiment")


def mode(parser: argparse.ArgumentParser, default: str | None = MODES[0], what: str = "") -> None:
    """Adds `--mode`, one of `sim.study.MODES`."""
    what = what or f"the spec's mode: {', '.join(MODES)}"
    parser.add_argument("--mode", choices=MODES, default=default, help=what)


def seed(parser: argparse.ArgumentParser, what: str = "random seed") -> None:
    """Adds `--seed`: an integer in [0, `MAX_SEED`] (default 0)."""
    parser.add_argument("--seed", type=count(0, MAX_SEED), default=0, help=what)


def target_name(text: str) -> str:
    """Returns an F_p target: a published name (`sim.study.TARGETS`) or a .json file that
    exists (read and checked by `workers.evaluators.resolve_target`).

    Raises:
        argparse.ArgumentTypeError: naming the value and what is allowed.
    """
    if text in TARGETS or (text.endswith(".json") and Path(text).is_file()):
        return text
    raise argparse.ArgumentTypeError(
        f"{text!r} is not allowed: {', '.join(TARGETS)} or an existing .json target file"
    )


def target(parser: argparse.ArgumentParser) -> None:
    """Adds `--target`: the F_p target (`target_name`)."""
    what = f"F_p target: {', '.join(TARGETS)} or a JSON file"
    parser.add_argument("--target", type=target_name, default=TARGETS[0], help=what)


def walk_seconds(text: str) -> float:
    """Returns a walk's length in seconds, a number in (0, `MAX_SECONDS`].

    Raises:
        argparse.ArgumentTypeError: naming the value and what is allowed.
    """
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or not 0 < value <= MAX_SECONDS:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not allowed: a number of seconds in (0, {MAX_SECONDS:g}]"
        )
    return value


def seconds(
    parser: argparse.ArgumentParser, what: str = "seconds per walk", *, required: bool = False
) -> None:
    """Adds `--seconds`: a walk's length (default: Table I's 10 s)."""
    if required:
        parser.add_argument("--seconds", type=walk_seconds, required=True, help=what)
    else:
        parser.add_argument("--seconds", type=walk_seconds, default=WALK_SECONDS, help=what)


def count(lowest: int, highest: int):
    """Returns an argparse type: an integer in [lowest, highest]."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = lowest - 1
        if not lowest <= value <= highest:
            raise argparse.ArgumentTypeError(
                f"{text!r} is not allowed: an integer in [{lowest}, {highest}]"
            )
        return value

    return parse


def repeats(parser: argparse.ArgumentParser, what: str = "walks on this floor") -> None:
    """Adds `--repeats`: walks per robot and floor (Table I's 5), at most `MAX_REPEATS`."""
    parser.add_argument("--repeats", type=count(1, MAX_REPEATS), default=5, help=what)


def robot(parser: argparse.ArgumentParser) -> None:
    """Adds `--robot`: which of Table I's robots (`sim.study.ROBOTS`)."""
    parser.add_argument(
        "--robot", default=ROBOTS[0], choices=ROBOTS, help="which robot of Table I's row"
    )


def robot_model(parser: argparse.ArgumentParser) -> None:
    """Adds `--model`: the robot model a walk runs on (`sim.robot.hexapod.ROBOT_MODELS`)."""
    parser.add_argument(
        "--model",
        default=ROBOT_MODELS[0],
        choices=ROBOT_MODELS,
        help="lean (legs reduced to what meets the floor) or full (every beam a body; slower)",
    )


def floor(parser: argparse.ArgumentParser, *, required: bool = False, default: str = FLAT):
    """Adds `--floor`, one of `sim.robot.hexapod.FLOORS`."""
    if required:
        parser.add_argument("--floor", required=True, choices=tuple(FLOORS), help="the floor")
    else:
        parser.add_argument("--floor", default=default, choices=tuple(FLOORS), help="the floor")


def ray_address(parser: argparse.ArgumentParser) -> None:
    """Adds `--address`: the Ray cluster to join."""
    parser.add_argument("--address", help="Ray address (default: RAY_ADDRESS, else start one)")


def robot_config(parser: argparse.ArgumentParser) -> None:
    """Adds `--config`: the robot's TOML (default: the one linkevo ships)."""
    what = f"robot TOML (default: the shipped {ROBOT_CONFIG})"
    parser.add_argument("--config", type=Path, default=None, help=what)


def force(parser: argparse.ArgumentParser, what: str = "replace an existing --out file") -> None:
    """Adds `--force`: an existing output file is replaced instead of refused."""
    parser.add_argument("--force", action="store_true", help=what)


def _writable(folder: Path, option: str, shown: Path) -> None:
    """Raises CliError unless a file can be created in `folder` or, where it does not exist
    yet, in its nearest existing ancestor (tried with a file created and removed: a mode bit
    or a read-only mount says no alike)."""
    import tempfile

    from linkevo.orchestrator.cli import CliError

    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise CliError(f"{option} {str(shown)!r}: {str(existing)!r} is a file, not a folder")
    try:
        with tempfile.NamedTemporaryFile(dir=existing, prefix=".linkevo-write-test."):
            pass
    except OSError as exc:
        raise CliError(
            f"{option} {str(shown)!r}: cannot write in {str(existing)!r} ({exc.strerror}); "
            "choose a folder you can write to"
        ) from None


def output_folder(path: Path, option: str = "--out") -> Path:
    """Returns `path` once it is checked as an output folder, before any work: a folder (new
    or existing) that can be written in.

    Raises:
        CliError: naming the path and what is wrong.
    """
    from linkevo.orchestrator.cli import CliError

    if path.exists() and not path.is_dir():
        raise CliError(f"{option} {str(path)!r} is a file; allowed: a folder (new or existing)")
    _writable(path, option, path)
    return path


def output_file(path: Path, *, force: bool, suffix: str, option: str = "--out") -> Path:
    """Returns `path` once it is checked as an output file, before any work: it ends in
    `suffix`, its folder can be written in, and it does not exist unless `force`.

    Raises:
        CliError: naming the path and what is wrong.
    """
    from linkevo.orchestrator.cli import CliError

    if path.suffix != suffix or path.is_dir():
        raise CliError(f"{option} {str(path)!r}: allowed a {suffix} file")
    if path.exists() and not force:
        raise CliError(f"{option} {str(path)!r} exists; add --force to replace it")
    _writable(path.parent, option, path)
    return path


def linkevo_command(*words: str) -> str:
    """Returns a linkevo command line, quoted for a shell, as the user can run it: `linkevo`
    when that name finds this program, else its path (an environment that is not
    activated), else `python -m linkevo.orchestrator`."""
    import os
    import shutil

    program = Path(sys.argv[0])
    if program.name != "linkevo":
        head = [sys.executable, "-m", "linkevo.orchestrator"]
    else:
        found = shutil.which("linkevo")
        if found and Path(found).resolve() == program.resolve():
            head = ["linkevo"]
        elif program.resolve().is_relative_to(Path.cwd()):
            head = [os.path.relpath(program)]
        else:
            head = [str(program)]
    return shlex.join([*head, *words])
