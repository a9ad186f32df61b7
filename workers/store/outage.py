"""Provides what a grid does when its MLflow tracking server stops answering: notice it
(`ServerWatch`, the driver), wait for it within a limit (`patiently`, the trials), and give
up cleanly (`ServerLost`).

A trial keeps computing while the server is away: its metrics stay in memory and go out
when the server answers again (`MlflowRecorder`); its end-of-trial files wait for it. If
the server has not answered for `OUTAGE_LIMIT_S` (config key `server_outage_s`), the
driver stops the grid and prints the `--resume` command, and a trial gives up.
"""

from __future__ import annotations

import os
import threading
import time
import urllib.request
from collections.abc import Callable
from typing import TypeVar

from linkevo.sim.errors import LinkevoError

OUTAGE_LIMIT_S = 300.0
"""How long a tracking server may stay silent before the grid stops (default of the
config key `server_outage_s`)."""
CHECK_S = 5.0
"""How often the driver asks the server's /health while it runs a grid (so an outage is
noticed within this plus `HEALTH_TIMEOUT_S`, well within 30 s)."""
HEALTH_TIMEOUT_S = 3.0
QUICK_HTTP = {"MLFLOW_HTTP_REQUEST_MAX_RETRIES": "1", "MLFLOW_HTTP_REQUEST_TIMEOUT": "10"}
"""MLflow's HTTP settings in a trial task: a request to a silent server fails within
about 20 s (MLflow's default retries for minutes), so the trial can keep computing and
try again later."""

T = TypeVar("T")


class ServerLost(LinkevoError, RuntimeError):
    """The tracking server did not answer for longer than the limit; says which and since
    when."""

    def __init__(self, uri: str, since: float, limit_s: float, during: str = "") -> None:
        clock = time.strftime("%H:%M:%S", time.localtime(since))
        super().__init__(
            f"the tracking server {uri} has not answered since {clock} "
            f"({time.time() - since:.0f} s, limit server_outage_s = {limit_s:g} s)"
            + (f"; it failed {during}" if during else "")
        )
        self.uri, self.since = uri, since


def is_server(uri: str) -> bool:
    return uri.startswith(("http://", "https://"))


def answers(uri: str, timeout: float = HEALTH_TIMEOUT_S) -> bool:
    """Whether the tracking server at `uri` answers its /health (a store that is not a
    server always does)."""
    if not is_server(uri):
        return True
    try:
        with urllib.request.urlopen(uri.rstrip("/") + "/health", timeout=timeout) as reply:
            return reply.status == 200
    except OSError:
        return False


def use_quick_http() -> None:
    """Sets `QUICK_HTTP` in this process (a trial task's worker), unless the user set them."""
    for key, value in QUICK_HTTP.items():
        os.environ.setdefault(key, value)


def patiently(call: Callable[[], T], uri: str, limit_s: float) -> T:
    """Returns `call()`, retried every `CHECK_S` while it fails because the server at `uri`
    does not answer, for up to `limit_s` from the first failure.

    Raises:
        ServerLost: the server stayed silent past the limit.
        Exception: whatever `call` raised while the server answered (a real error).
    """
    since = None
    while True:
        try:
            return call()
        except Exception:
            if answers(uri):
                raise
        since = since or time.time()
        if time.time() - since > limit_s:
            raise ServerLost(uri, since, limit_s)
        time.sleep(CHECK_S)


class ServerWatch:
    """Asks a tracking server's /health every `CHECK_S` in a thread while a grid runs;
    `down_since` is when it stopped answering (None while it answers, or for a store that
    is not a server)."""

    def __init__(self, uri: str, limit_s: float = OUTAGE_LIMIT_S) -> None:
        self.uri = uri
        self.limit_s = limit_s
        self.down_since: float | None = None
        self._told: float | None = None  # the outage the user was told about
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="server-watch", daemon=True)
        if is_server(uri):
            self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(CHECK_S):
            if answers(self.uri):
                self.down_since = None
            elif self.down_since is None:
                self.down_since = time.time()

    def news(self) -> str | None:
        """Returns a line for the user when the server went silent or came back since the
        last call, else None."""
        down = self.down_since
        if down is not None and self._told is None:
            self._told = down
            clock = time.strftime("%H:%M:%S", time.localtime(down))
            return (
                f"the tracking server {self.uri} has not answered since {clock}; trials keep "
                f"computing and hold their metrics; the grid stops if it is silent for "
                f"{self.limit_s:g} s (server_outage_s)"
            )
        if down is None and self._told is not None:
            silent, self._told = time.time() - self._told, None
            return f"the tracking server {self.uri} answers again (silent about {silent:.0f} s)"
        return None

    def check(self) -> None:
        """Raises ServerLost once the server has been silent for longer than the limit."""
        down = self.down_since
        if down is not None and time.time() - down > self.limit_s:
            raise ServerLost(self.uri, down, self.limit_s)

    def close(self) -> None:
        self._stop.set()
