"""Provides ResultPool: reusable Evaluation buffers, so batches do not page in new memory.

Fresh result arrays for a batch of 5,000 (about 3.7 MB) cost a few milliseconds of page
faults on every call; a buffer whose arrays are no longer referenced anywhere can be
written again instead. Each buffer is one uint8 array (a `Root`) that every handed-out
array is a view of, so its reference count says whether any of them is still alive.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Protocol

import numpy as np

from linkevo.sim.evaluation import Evaluation

KEEP = 4
"""Buffers a pool keeps; older ones are released (arrays still held stay valid)."""


class ResultBuffer(Protocol):
    """Room for the Evaluation of up to `capacity` genomes."""

    capacity: int

    @property
    def busy(self) -> bool:
        """Whether an array handed out by `evaluation()` is still alive."""
        ...

    def evaluation(self) -> Evaluation:
        """Returns the buffer's Evaluation (capacity rows), as views into it."""
        ...

    def release(self) -> None:
        """Gives up the buffer's resources (arrays still held stay valid)."""
        ...


class Root:
    """A uint8 array that tells whether any view of it is alive.

    Numpy gives every view of `array` (and every view of those) `array` as its base, so
    the array's reference count rises above its count at construction exactly while one
    exists. The array is made here (by `make()`), so no caller holds it when the idle
    count is taken, and the count is always taken by the same code, whatever the
    interpreter's own references on the stack.
    """

    def __init__(self, make: Callable[[], np.ndarray]):
        self.array = make()
        self._idle = self._count()

    def _count(self) -> int:
        return sys.getrefcount(self.array)

    @property
    def busy(self) -> bool:
        """Whether a view of the array exists."""
        return self._count() > self._idle


class MemoryBuffer:
    """A ResultBuffer in this process's memory."""

    def __init__(self, capacity: int, n_angles: int, n_objectives: int):
        self.capacity = capacity
        self._shape = (capacity, n_angles, n_objectives)
        self._root = Root(lambda: np.empty(Evaluation.nbytes_for(*self._shape), np.uint8))

    @property
    def busy(self) -> bool:
        return self._root.busy

    def evaluation(self) -> Evaluation:
        return Evaluation.empty(*self._shape, buffer=self._root.array)

    def release(self) -> None:
        """Nothing to give up: the memory goes with the last array."""


class ResultPool:
    """Hands out a buffer for n rows that nobody holds, making one when there is none.

    Args:
        make: `make(n)` returns a new buffer of capacity n.
        keep: buffers kept for reuse (the oldest is released beyond it).
    """

    def __init__(self, make: Callable[[int], ResultBuffer], keep: int = KEEP):
        self._make = make
        self._keep = keep
        self._buffers: list[ResultBuffer] = []

    def free(self, n: int) -> ResultBuffer:
        """Returns a buffer of capacity >= n with no live arrays."""
        for buffer in self._buffers:
            if buffer.capacity >= n and not buffer.busy:
                return buffer
        buffer = self._make(n)
        self._buffers.append(buffer)
        if len(self._buffers) > self._keep:
            self._buffers.pop(0).release()
        return buffer

    def close(self) -> None:
        """Releases every buffer (idempotent)."""
        for buffer in self._buffers:
            buffer.release()
        self._buffers = []
