"""Provides `Lease`: one writer per grid and per walk map. A grid's launch or resume (and a
walk map's run) takes the lease in the store before it writes anything, renews it while it
runs and hands it back at the end; a second writer of the same thing is refused while the
lease is held.

A lease is an experiment tag (`run_layout.lease_tag`) holding the holder's host, pid,
start and last renewal, so it works on every store linkevo writes to (sqlite, a tracking
server, a database). A holder that dies stops renewing: its lease expires `LEASE_TTL_S`
after the last renewal, at once when it ran on this host and its process is gone, so a
`--resume` after a crash needs no manual unlock.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import threading
import time
import uuid
from dataclasses import asdict, dataclass

from linkevo.sim.errors import LinkevoError
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.artifacts import process_alive
from linkevo.workers.store.runs import RunStore
from linkevo.workers.store.tracking import store_lock

LEASE_TTL_S = 60.0
"""A lease not renewed for this long is free."""
RENEW_S = 10.0
"""How often a running driver renews its lease."""
CONFIRM_S = 1.0
"""On a store without a file lock (a server), how long a new holder waits before reading
the lease back: of two drivers that took it at once, the one whose write landed last
keeps it and the other is refused."""


class Busy(LinkevoError):
    """Another process holds the lease; the message says who and what to do."""


@dataclass(frozen=True)
class Holder:
    """Who holds a lease (times are seconds since the epoch)."""

    host: str
    pid: int
    started: float
    renewed: float
    token: str

    def alive(self, now: float) -> bool:
        """Whether the lease still binds: renewed within the TTL by a process that (when
        it ran on this host) still exists."""
        if self.host == socket.gethostname() and not process_alive(self.pid):
            return False
        return now - self.renewed < LEASE_TTL_S

    def describe(self, now: float) -> str:
        since = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(self.started))
        return (
            f"pid {self.pid} on {self.host}, running since {since}, last renewed "
            f"{now - self.renewed:.0f} s ago"
        )


@dataclass(frozen=True)
class Subject:
    """What a lease guards: its tag's name (`run_layout.lease_tag`) and how the refusal
    reads ("grid 3f2a is being run by another driver pid ...; {advice}")."""

    name: str
    what: str
    doer: str
    advice: str

    @classmethod
    def grid(cls, grid_id: str) -> Subject:
        return cls(
            grid_id,
            f"grid {grid_id} is being run",
            "driver",
            "two drivers on one grid would undo each other's trials. Wait for it to finish "
            "(or stop it with Ctrl-C)",
        )

    @classmethod
    def walk_map(cls, run_id: str, trial_key: str) -> Subject:
        return cls(
            f"walkmap.{run_id}",
            f"the walk map of run {run_id} ({trial_key}) is being made",
            "linkevo walkmap",
            "two at once would each log a map without the other's rows. Wait for it to "
            "finish (or stop it with Ctrl-C), then walk what it lacks with --resume",
        )


class Lease:
    """A lease, held by this process from `take` to `release`."""

    def __init__(self, store: RunStore, subject: Subject, holder: Holder) -> None:
        self._store, self._subject = store, subject
        self._key = layout.lease_tag(subject.name)
        self._holder = holder
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._renew, name="lease", daemon=True)

    @classmethod
    def take(cls, store: RunStore, subject: Subject) -> Lease:
        """Takes the lease and starts renewing it.

        Raises:
            Busy: a live process holds it (named, with what to do).
        """
        now = time.time()
        me = Holder(socket.gethostname(), os.getpid(), now, now, uuid.uuid4().hex)
        lease = cls(store, subject, me)
        with store_lock(store.uri):
            lease._refuse_if_held(store, now)
            lease._write(store, me)
        if not store.uri.startswith("sqlite:///"):
            time.sleep(CONFIRM_S)
            lease._refuse_if_held(store, time.time())
        lease._thread.start()
        return lease

    @classmethod
    def refuse_if_held(cls, store: RunStore, subject: Subject) -> None:
        """Raises Busy when a live process holds the lease (checked, not taken)."""
        now = time.time()
        nobody = Holder("", 0, now, now, "")
        cls(store, subject, nobody)._refuse_if_held(store, now)

    def release(self, write: bool = True) -> None:
        """Stops renewing and hands the lease back (if it is still this driver's); with
        `write` False (the store is unreachable) it only stops renewing, and the lease
        expires by itself."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()
        if not write:
            return
        store = self._own_store()
        with contextlib.suppress(Exception):  # a store that went away keeps a lease that expires
            current = self._read(store)
            if current is not None and current.token == self._holder.token:
                store.delete_experiment_tag(self._key)

    def _own_store(self) -> RunStore:
        """A store of this process's own (the renewing thread's, and the release's)."""
        return RunStore(self._store.uri, experiment_id=self._store.experiment_id)

    def _refuse_if_held(self, store: RunStore, now: float) -> None:
        current = self._read(store)
        if current is None or current.token == self._holder.token or not current.alive(now):
            return
        expires = LEASE_TTL_S - (now - current.renewed)
        subject = self._subject
        raise Busy(
            f"{subject.what} by another {subject.doer} {current.describe(now)}; "
            f"{subject.advice}; if it died on another machine, its lease expires in "
            f"{expires:.0f} s and --resume then takes over"
        )

    def _read(self, store: RunStore) -> Holder | None:
        text = store.experiment_tag(self._key)
        if text is None:
            return None
        try:
            return Holder(**json.loads(text))
        except (TypeError, ValueError):
            return None  # a damaged lease binds nobody

    def _write(self, store: RunStore, holder: Holder) -> None:
        store.set_experiment_tag(self._key, json.dumps(asdict(holder)))

    def _renew(self) -> None:
        store = self._own_store()
        while not self._stop.wait(RENEW_S):
            holder = Holder(**{**asdict(self._holder), "renewed": time.time()})
            with contextlib.suppress(Exception):  # an unreachable store: try again next time
                self._write(store, holder)
