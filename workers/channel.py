"""Provides a side channel from a caller to an actor on the same machine.

A Ray actor call costs 2.5–3 ms here once the actor has been busy for a while (the
request and the reply each wake several threads across processes), against 15–20 ms of
simulation per batch. An evaluator actor therefore also serves requests on a Unix socket in
the abstract namespace (no file to clean up) from one thread of its own, and a co-located
caller sends each batch's (layout, first row, last row) there: a one-genome batch costs
about 0.4 ms more than in process this way, everything included. Ray still creates,
places, restarts and kills the actor, and carries every call the channel cannot
(docs/grid.md, "Evaluator transport").
"""

from __future__ import annotations

import threading
import uuid
from collections.abc import Callable
from multiprocessing.connection import Client, Connection, Listener

FAMILY = "AF_UNIX"


def serve(handler: Callable[..., object], authkey: bytes, setup: Callable[[], None]) -> str:
    """Starts a daemon thread that answers one caller's requests; returns its address.

    Each request is a tuple of arguments; the reply is `handler(*request)`, or the
    exception it raised. The thread runs `setup()` first (numba's thread count is per
    thread) and ends when the caller closes its end.
    """
    address = f"\0linkevo-channel-{uuid.uuid4().hex}"
    listener = Listener(address, family=FAMILY, authkey=authkey)

    def run() -> None:
        setup()
        try:
            with listener.accept() as conn:
                while True:
                    try:
                        request = conn.recv()
                    except (EOFError, OSError):
                        return
                    try:
                        answer = handler(*request)
                    except Exception as exc:  # handed to the caller, who raises it
                        answer = exc
                    conn.send(answer)
        finally:
            listener.close()

    threading.Thread(target=run, name="linkevo-channel", daemon=True).start()
    return address


def connect(address: str, authkey: bytes) -> Connection:
    """Returns the caller's end of the channel served at `address`."""
    return Client(address, family=FAMILY, authkey=authkey)


class ChannelLost(Exception):
    """The actor's end of some channels went away (the actor died or was killed).

    Attributes:
        lost: the keys of those channels.
        answers: the replies read on the others.
    """

    def __init__(self, lost: list[int], answers: dict[int, object]):
        super().__init__(f"lost the side channel to actors {lost}")
        self.lost = lost
        self.answers = answers


def replies(conns: dict[int, Connection]) -> dict[int, object]:
    """Returns the reply on each connection (all are read, so none is left queued).

    Raises:
        ChannelLost: naming the keys of the connections whose other end is gone; the
            replies that did come are on the exception (`answers`).
        Exception: the first exception a handler raised, once every reply is read.
    """
    answers: dict[int, object] = {}
    lost: list[int] = []
    for key, conn in conns.items():
        try:
            answers[key] = conn.recv()
        except (EOFError, OSError):
            lost.append(key)
    if lost:
        raise ChannelLost(lost, answers)
    for answer in answers.values():
        if isinstance(answer, Exception):
            raise answer
    return answers
