"""Provides ResultPool: reusable Evaluation buffers, so batches do not page in new memory.

Fresh result arrays for a batch of 5,000 (about 3.7 MB) cost a few milliseconds of page
faults on every call; a buffer whose arrays are no longer referenced anywhere can be
written again instead. Each buffer is one uint8 array that every handed-out array is a
view of, so its reference count says whether any of them is still alive.
"""

from __future__ import annotations

import sys

import numpy as np

from linkevo.sim.linkage.evaluation import Evaluation

KEEP = 4
"""Buffers a pool keeps; older ones are dropped (arrays still held stay valid)."""


class MemoryBuffer:
    """Room for the Evaluation of up to `capacity` genomes, in one uint8 array.

    Numpy gives every view of the array (and every view of those) the array as its base,
    so the array's reference count rises above its count at construction exactly while
    one exists. The array is made here, so no caller holds it when the idle count is
    taken, and the count is always taken by the same code.
    """

    def __init__(self, capacity: int, n_angles: int, n_objectives: int):
        self.capacity = capacity
        self._shape = (capacity, n_angles, n_objectives)
        self._array = np.empty(Evaluation.nbytes_for(*self._shape), np.uint8)
        self._idle = self._count()

    def _count(self) -> int:
        return sys.getrefcount(self._array)

    @property
    def busy(self) -> bool:
        """Whether an array handed out by `evaluation()` is still alive."""
        return self._count() > self._idle

    def evaluation(self) -> Evaluation:
        """Returns the buffer's Evaluation (capacity rows), as views into it."""
        return Evaluation.empty(*self._shape, buffer=self._array)


class ResultPool:
    """Hands out a buffer for n rows that nobody holds, making one when there is none.

    Args:
        n_angles, n_objectives: the shape of each row's results.
        keep: buffers kept for reuse (the oldest is dropped beyond it).
    """

    def __init__(self, n_angles: int, n_objectives: int, keep: int = KEEP):
        self._shape = (n_angles, n_objectives)
        self._keep = keep
        self._buffers: list[MemoryBuffer] = []

    def free(self, n: int) -> MemoryBuffer:
        """Returns a buffer of capacity >= n with no live arrays."""
        for buffer in self._buffers:
            if buffer.capacity >= n and not buffer.busy:
                return buffer
        buffer = MemoryBuffer(n, *self._shape)
        self._buffers.append(buffer)
        if len(self._buffers) > self._keep:
            self._buffers.pop(0)
        return buffer
