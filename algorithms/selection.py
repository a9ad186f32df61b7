"""Provides tournament selection on a batch of losses."""

from __future__ import annotations

import numpy as np


def tournament(
    loss: np.ndarray, k: int, rng: np.random.Generator, tournsize: int = 3
) -> np.ndarray:
    """Returns the indices of `k` tournament winners (lowest loss of `tournsize` aspirants).

    Aspirants are drawn uniformly with replacement, as DEAP's `selTournament` does; ties
    go to the first aspirant drawn.

    Args:
        loss: (N,) losses to minimise.
        k: number of winners.
        rng: the random source.
        tournsize: aspirants per tournament.

    Returns:
        (k,) int64 indices into `loss`.
    """
    aspirants = rng.integers(0, loss.shape[0], size=(k, tournsize))
    best = np.argmin(loss[aspirants], axis=1)
    return aspirants[np.arange(k), best]
