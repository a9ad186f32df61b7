"""Provides the process sessions a local cluster is made of: start a command in a session of
its own, list and stop a session's processes, find a free loopback port.

Each `ray start`, `mlflow server` and PostgreSQL runs as the leader of its own session, so
stopping a session stops exactly that process tree and nothing else on the machine.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import socket
import subprocess
import time
import urllib.request
from pathlib import Path

from linkevo.sim.errors import LinkevoError

STOP_TIMEOUT_S = 20.0
"""How long a session's leader has to stop its children before they are killed."""


class ClusterError(LinkevoError, RuntimeError):
    """The local cluster cannot be started or stopped; the message says why and what to do."""


def spawn(command: list[str], log: Path, env: dict[str, str]) -> int:
    with open(log, "wb") as out:
        process = subprocess.Popen(
            command,
            stdout=out,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            env=env,
            start_new_session=True,
        )
    return process.pid


def stop_with_parent() -> None:
    """Run in a child between fork and exec (`preexec_fn`): Linux sends it SIGTERM when the
    process that started it dies, however it dies (SIGKILL included), so a server started
    for a command never outlives that command."""
    pr_set_pdeathsig = 1
    ctypes.CDLL(None, use_errno=True).prctl(pr_set_pdeathsig, signal.SIGTERM)


def answers(url: str) -> bool:
    try:
        with urllib.request.urlopen(url, timeout=2) as reply:
            return reply.status == 200
    except OSError:
        return False


def stop_session(sid: int, force: bool = False) -> None:
    """Stops the process tree of session `sid`: SIGTERM to its leader (`ray start --block`
    and `mlflow server` shut their children down in order), SIGKILL to what is left
    (at once with `force`)."""
    if not force:
        with contextlib.suppress(ProcessLookupError):
            os.kill(sid, signal.SIGTERM)
        deadline = time.monotonic() + STOP_TIMEOUT_S
        while session_members(sid) and time.monotonic() < deadline:
            time.sleep(0.1)
    for pid in session_members(sid):
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    while session_members(sid):
        time.sleep(0.1)


def session_members(sid: int) -> list[int]:
    """Pids of the live (not zombie) processes whose session id is `sid`."""
    members = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2 :].split()
        if fields[0] != "Z" and int(fields[3]) == sid:  # state, ppid, pgrp, session
            members.append(int(entry.name))
    return members


def alive_sessions(sids: list[int]) -> list[int]:
    return [pid for sid in sids for pid in session_members(sid)]


def command_lines() -> list[tuple[int, list[str]]]:
    """Returns (pid, command-line words) of every other process of this machine."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit() and int(entry.name) != os.getpid():
            try:
                args = (entry / "cmdline").read_bytes().decode(errors="replace")
            except OSError:
                continue
            found.append((int(entry.name), args.split("\0")))
    return found


def processes_using(*paths: str) -> list[int]:
    """Pids whose command line names one of `paths` (PostgreSQL's own sessions)."""
    return [pid for pid, words in command_lines() if any(p in "\0".join(words) for p in paths)]


def free_port(wanted: int, name: str) -> int:
    if wanted == 0:
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            return probe.getsockname()[1]
    if in_use(wanted):
        raise ClusterError(f"{name} {wanted} is already in use; pick another or pass 0 (any free)")
    return wanted


def in_use(port: int) -> bool:
    """Whether a process listens on `port` (a closed connection's TIME_WAIT does not count)."""
    with socket.socket() as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind(("127.0.0.1", port))
        except OSError:
            return True
    return False
