"""Provides the `linkevo` command line: one entry point that dispatches to subcommands."""

from __future__ import annotations

import argparse
import importlib
import importlib.metadata
import sys

from linkevo.sim.errors import LinkevoError

# Each subcommand module exposes `register(subparsers)`; the registered parser sets
# `func(args) -> int`. Modules are imported only when the CLI starts, so one slow or
# heavy import (Ray, torch) is paid only by the commands that need it at run time.
COMMAND_MODULES = (
    "linkevo.orchestrator.commands.sim",
    "linkevo.orchestrator.commands.trial",
    "linkevo.orchestrator.commands.grid",
    "linkevo.orchestrator.commands.ui",
    "linkevo.orchestrator.commands.report",
    "linkevo.orchestrator.commands.pull",
    "linkevo.orchestrator.commands.explore",
    "linkevo.orchestrator.commands.walkmap",
    "linkevo.orchestrator.commands.walkmodel",
    "linkevo.orchestrator.commands.cluster",
    "linkevo.orchestrator.commands.hexapod",
)


class CliError(LinkevoError):
    """Bad command-line input; the message names the bad value and what is allowed."""


class DefaultsFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Appends "(default: ...)" to each option's help unless the help already says it."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        if action.help and "default" in action.help:
            return action.help
        return super()._get_help_string(action)


class Parser(argparse.ArgumentParser):
    """An argument parser whose help shows every option's default (its subcommands too)."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        kwargs.setdefault("formatter_class", DefaultsFormatter)
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]


def version() -> str:
    """Returns the installed linkevo version."""
    try:
        return importlib.metadata.version("linkevo")
    except importlib.metadata.PackageNotFoundError:
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    """Returns the parser with every available subcommand registered."""
    parser = Parser(
        prog="linkevo",
        description="Evolve mechanical linkages for legged robots and run the experiments.",
    )
    parser.add_argument("--version", action="version", version=f"linkevo {version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name == name:
                continue
            raise
        module.register(sub)
    return parser


def quiet_libraries() -> None:
    """Keeps the libraries' routine messages off the terminal, so that what linkevo prints
    is what the user must know: MLflow's INFO lines (creating a store's tables, say) and
    download progress bars, Ray's notice that token authentication is on (it is, and
    the embedded instance needs nothing from the user), and the colour codes of Ray's
    worker-log prefixes (`EscapedStream` would show them as text). Set in the environment, so Ray
    workers and MLflow subprocesses inherit it; a value the user set is kept."""
    import logging
    import os

    os.environ.setdefault("MLFLOW_LOGGING_LEVEL", "WARNING")
    os.environ.setdefault("RAY_COLOR_PREFIX", "0")  # Ray's worker-log prefixes uncoloured
    os.environ.setdefault("MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR", "false")
    notice = "ray._private.authentication.authentication_token_setup"
    logging.getLogger(notice).setLevel(logging.ERROR)


def _store_damage(exc: BaseException) -> str | None:
    """Returns SQLite's words when `exc` (or what caused it) says the store's file is
    damaged (past the header checks of `tracking.check_store_file`), else None."""
    import sqlite3

    while exc is not None:
        if type(exc) is sqlite3.DatabaseError:  # not its subclasses: "locked" is not damage
            return str(exc)
        exc = exc.__cause__ or exc.__context__
    return None


_CONTROLS = {
    code: f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}"
    for code in (
        *range(0x00, 0x20),
        *range(0x7F, 0xA0),
        *range(0x202A, 0x202F),  # bidirectional embeddings and overrides
        *range(0x2066, 0x206A),  # bidirectional isolates
    )
    if chr(code) not in "\t\n\r"
}
"""Characters that would steer a terminal (escape sequences, bells, backspaces, text
direction), each mapped to its visible escape."""


class EscapedStream:
    """A text stream that writes control characters as visible escapes (`\\x1b`), so
    text read from a store or a document (a run's tags, a linkage's meta) can neither
    clear the screen nor retitle the window. Tabs, newlines and carriage returns (progress
    bars) pass as they are."""

    def __init__(self, stream) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        self._stream.write(text.translate(_CONTROLS))
        return len(text)

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def main(argv: list[str] | None = None) -> int:
    """Runs the CLI and returns the process exit code; everything it prints goes through
    `EscapedStream`."""
    streams = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = EscapedStream(sys.stdout), EscapedStream(sys.stderr)
    try:
        return _main(argv)
    finally:
        sys.stdout, sys.stderr = streams


def terminate_as_interrupt(signum: int, frame: object) -> None:
    """SIGTERM stops a command as Ctrl-C does: a KeyboardInterrupt("SIGTERM") that every
    command's interrupt handling sees (what was done is kept, runs are ended KILLED, the
    line that resumes is printed)."""
    raise KeyboardInterrupt("SIGTERM")


def os_error_text(exc: OSError) -> str:
    """Returns an OS error on a path in one line: the file, what the system says, and what
    to do."""
    where = exc.filename if exc.filename is not None else "a file"
    return (
        f"{where}: {exc.strerror or exc}; check the path (it must exist, be of the kind "
        "asked for and be readable, or writable for an output) and the free disk space"
    )


def _main(argv: list[str] | None) -> int:
    import signal
    import threading

    quiet_libraries()
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, or a value an option refuses (argparse printed it)
        return int(exc.code or 0)
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, terminate_as_interrupt)
    try:
        return int(args.func(args) or 0)
    except LinkevoError as exc:
        print(f"linkevo {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # a path the user gave: missing, a folder, unreadable, a full disk
        print(f"linkevo {args.command}: error: {os_error_text(exc)}", file=sys.stderr)
        return 2
    except UnicodeDecodeError as exc:
        print(
            f"linkevo {args.command}: error: a file it read is not UTF-8 text ({exc.reason} "
            f"at byte {exc.start}); give the file linkevo wrote, not a binary or another "
            "encoding",
            file=sys.stderr,
        )
        return 2
    except Exception as exc:
        damage = _store_damage(exc)
        if damage is None:
            raise
        print(
            f"linkevo {args.command}: error: the MLflow store is damaged ({damage}); restore "
            "it from a backup, or move it away to start a new store",
            file=sys.stderr,
        )
        return 2
    except KeyboardInterrupt as exc:
        by = "SIGTERM" if exc.args == ("SIGTERM",) else "Ctrl-C"
        print(f"linkevo {args.command}: interrupted ({by})", file=sys.stderr)
        return interrupted_code(exc)


def interrupted_code(exc: KeyboardInterrupt) -> int:
    """Returns the exit status of a command stopped by a signal: 143 for SIGTERM
    (`terminate_as_interrupt`), 130 for Ctrl-C, as a shell reports them."""
    return 143 if exc.args == ("SIGTERM",) else 130
