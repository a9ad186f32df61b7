"""Stops what a killed driver's local Ray instance leaves behind.

A driver that starts a local Ray instance starts this module as
`python -m linkevo.orchestrator.reaper TOKEN` (`ray_connection._start_reaper`), holding
the write end of its stdin, and puts the token in the environment its Ray processes
inherit (`SESSION_ENV`). While the driver runs, the reaper notes the driver's process tree
every `SNAPSHOT_S` (Ray's GCS, raylet, agents and workers all descend from it). When the
driver ends, however it ends (SIGKILL included), the pipe closes; the reaper gives a clean
`ray.shutdown()` `GRACE_S` to finish, then kills whatever still runs of the last tree and
every process that carries the token (a worker started after the last note; Ray's agents
rename themselves and hide their environment, but they start first and are in the tree).
Without it, Ray's dashboard and runtime-env agents of a killed driver outlive it by
minutes, still listening, while they try to report the raylet's death.
"""

from __future__ import annotations

import contextlib
import os
import select
import signal
import sys
import time
from pathlib import Path

SESSION_ENV = "LINKEVO_RAY_SESSION"
"""The environment variable that marks a driver's Ray processes with its reaper's token."""
SNAPSHOT_S = 1.0
"""How often the driver's process tree is noted."""
GRACE_S = 2.0
"""Time a cleanly ending driver's Ray processes have to exit by themselves."""


def stat_of(pid: int) -> tuple[int, str] | None:
    """Returns (parent pid, start time in clock ticks) of a live process, else None."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return None if fields[0] == "Z" else (int(fields[1]), fields[19])  # type: ignore[return-value]


def tree(root: int) -> dict[int, str]:
    """Returns pid -> start time of every live process below `root` (not `root`)."""
    children: dict[int, list[int]] = {}
    started: dict[int, str] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            stat = stat_of(int(entry.name))
            if stat is not None:
                children.setdefault(stat[0], []).append(int(entry.name))
                started[int(entry.name)] = stat[1]
    found: dict[int, str] = {}
    todo = list(children.get(root, []))
    while todo:
        pid = todo.pop()
        if pid not in found and pid in started:
            found[pid] = started[pid]
            todo += children.get(pid, [])
    return found


def marked(token: str) -> dict[int, str]:
    """Returns pid -> start time of the live processes whose environment holds the token."""
    needle = f"{SESSION_ENV}={token}".encode()
    found = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            with contextlib.suppress(OSError):
                if needle in (entry / "environ").read_bytes().split(b"\0"):
                    stat = stat_of(int(entry.name))
                    if stat is not None:
                        found[int(entry.name)] = stat[1]
    return found


def main(token: str) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is for the driver
    driver, me = os.getppid(), os.getpid()
    last: dict[int, str] = {}
    while True:
        last = {pid: t for pid, t in tree(driver).items() if pid != me}
        ready, _, _ = select.select([sys.stdin], [], [], SNAPSHOT_S)
        if ready and not os.read(sys.stdin.fileno(), 4096):
            break  # the driver has ended
    time.sleep(GRACE_S)
    for _ in range(3):  # a process may start another while it is being stopped
        left = {**last, **marked(token)}
        for pid, start in left.items():
            stat = stat_of(pid)
            if stat is not None and stat[1] == start:  # the same process, not a reused pid
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)
        time.sleep(0.2)


if __name__ == "__main__":
    main(sys.argv[1])
