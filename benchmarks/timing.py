"""Provides the timing helper the benchmarks share."""

from __future__ import annotations

import time
from collections.abc import Callable


def best_seconds(fn: Callable[[], object], repeats: int) -> float:
    """Returns the best wall time of `fn()` over `repeats` calls, after one warm-up call.

    The best is the figure least disturbed by other load on a shared machine.
    """
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)
