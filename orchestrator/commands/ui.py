"""Provides `linkevo ui`: the MLflow UI on a local store, on the loopback address."""

from __future__ import annotations

import argparse
import signal
import subprocess
import sys
from pathlib import Path

from linkevo.orchestrator.cli import CliError
from linkevo.orchestrator.commands import options

APP = "linkevo"
"""The MLflow app plugin the UI runs (`orchestrator.ui_app`: MLflow's own app, every trial
of a grid on the runs table's first page)."""
LOG = "mlflow-ui.log"
"""The server's log, beside the store's database: its access log stays off the terminal."""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the `ui` subcommand."""
    ui = subparsers.add_parser(
        "ui",
        help="open the MLflow UI on the project's store (loopback only)",
        description=(
            "Serve the MLflow UI for the store on 127.0.0.1 and print its address; the "
            f"server logs to {LOG} beside the store. A store that a UI already serves is "
            "named with its address instead of a second server."
        ),
    )
    options.tracking_uri(
        ui, "store to browse (default: MLFLOW_TRACKING_URI, else the embedded runs/ store)"
    )
    ui.add_argument("--port", type=int, default=5000, help="loopback port of the UI")
    ui.set_defaults(func=run_ui)


def serving(uri: str) -> tuple[int, int] | None:
    """Returns (pid, port) of a UI that already serves the store `uri`, or None."""
    from linkevo.orchestrator.process_sessions import command_lines

    for pid, words in command_lines():
        if "mlflow" in " ".join(words[:3]) and "ui" in words and uri in words and "--port" in words:
            port = words[words.index("--port") + 1]
            if port.isdigit():
                return pid, int(port)
    return None


def run_ui(args: argparse.Namespace) -> int:
    """Runs `mlflow ui` on the store, bound to 127.0.0.1, until Ctrl-C or SIGTERM, which
    stop the server with it; killed outright, it takes the server with it too."""
    from linkevo.orchestrator.process_sessions import in_use, stop_session, stop_with_parent
    from linkevo.workers.store.runs import RunStore
    from linkevo.workers.store.tracking import (
        DEFAULT_EXPERIMENT,
        artifact_root_for,
        ensure_experiment,
        require_store,
        resolve_tracking_uri,
        ui_address,
    )

    uri = resolve_tracking_uri(args.tracking_uri)
    if uri.startswith(("http://", "https://")):
        raise CliError(
            f"--tracking-uri {uri!r} is already a server: open it in a browser; "
            "allowed here: a sqlite:/// URI or a store folder"
        )
    require_store(uri)
    experiment_id = None
    if RunStore(uri, DEFAULT_EXPERIMENT).has_experiment:
        experiment_id = ensure_experiment(uri)  # brings an older store's view up to date
    running = serving(uri)
    if running is not None:
        pid, port = running
        address = ui_address(f"http://127.0.0.1:{port}", experiment_id)
        raise CliError(
            f"a UI already serves this store (pid {pid}): open {address} , or stop it first"
        )
    if not 0 < args.port < 65536 or in_use(args.port):
        raise CliError(
            f"--port {args.port}: not a free loopback port (another program listens there, "
            "or it is out of range); pass a free one, e.g. --port 5001"
        )
    command = [sys.executable, "-m", "mlflow", "ui", "--app-name", APP, "--backend-store-uri", uri]
    artifacts = artifact_root_for(uri)
    if artifacts:
        command += ["--default-artifact-root", artifacts]
    command += ["--host", "127.0.0.1", "--port", str(args.port)]
    log = Path(uri.removeprefix("sqlite:///")).parent / LOG
    address = ui_address(f"http://127.0.0.1:{args.port}", experiment_id)
    with open(log, "a") as out:
        server = subprocess.Popen(
            command,
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,
            preexec_fn=stop_with_parent,
        )
    print(f"MLflow UI on {address}  (Ctrl-C stops it; server log: {log})", file=sys.stderr)

    def stop(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, stop)
    try:
        return server.wait()
    except KeyboardInterrupt:
        stop_session(server.pid)
        return 0
