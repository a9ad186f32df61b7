"""Provides NSGA-II's non-dominated sort, crowding distance, selection and 2-D hypervolume."""

from __future__ import annotations

from bisect import bisect_left

import numpy as np


def non_dominated_ranks(loss: np.ndarray) -> np.ndarray:
    """Returns the Pareto front index of every point (0 = non-dominated), minimising.

    An O(N log N) sweep for two objectives: points are visited in lexicographic order of
    (f0, f1); every front keeps the (f1, f0) key of its last member, and those keys rise
    with the front index, so a point joins the first front whose last key is not below its
    own (a lower key dominates it; an equal key is a duplicate, which does not dominate).

    Args:
        loss: (N, 2) objective values to minimise.

    Returns:
        (N,) int64 front indices.
    """
    if loss.ndim != 2 or loss.shape[1] != 2:
        raise ValueError(f"non_dominated_ranks needs (N, 2) losses, got {loss.shape}")
    n = loss.shape[0]
    f0, f1 = loss[:, 0], loss[:, 1]
    by_key = np.lexsort((f0, f1))
    key = np.empty(n, dtype=np.int64)
    sorted_pairs = loss[by_key][:, ::-1]
    new_key = np.ones(n, dtype=bool)
    new_key[1:] = np.any(sorted_pairs[1:] != sorted_pairs[:-1], axis=1)
    key[by_key] = np.cumsum(new_key) - 1
    ranks = np.empty(n, dtype=np.int64)
    last_keys: list[int] = []
    visit = np.lexsort((f1, f0))
    for i, k in zip(visit.tolist(), key[visit].tolist(), strict=True):
        front = bisect_left(last_keys, k)
        if front == len(last_keys):
            last_keys.append(k)
        else:
            last_keys[front] = k
        ranks[i] = front
    return ranks


def crowding_distance(loss: np.ndarray, ranks: np.ndarray) -> np.ndarray:
    """Returns NSGA-II's crowding distance of every point within its own front.

    As DEAP's `assignCrowdingDist`: per objective the front is stably re-sorted (ties keep
    the order of the previous objective's sort), its two ends get infinity, and every inner
    point adds (next - previous) / (M * (max - min)); an objective constant over the front
    adds nothing to the inner points.

    Args:
        loss: (N, M) objective values.
        ranks: (N,) front index of every point.

    Returns:
        (N,) float64 distances (inf at the ends of each front).
    """
    n, n_obj = loss.shape
    distance = np.zeros(n)
    position = np.arange(n)
    for m in range(n_obj):
        order = np.lexsort((position, loss[:, m], ranks))
        position = np.empty(n, dtype=np.int64)
        position[order] = np.arange(n)
        values = loss[order, m]
        front = ranks[order]
        first = np.ones(n, dtype=bool)
        first[1:] = front[1:] != front[:-1]
        last = np.ones(n, dtype=bool)
        last[:-1] = front[1:] != front[:-1]
        starts = np.flatnonzero(first)
        ends = np.flatnonzero(last)
        span = np.repeat(values[ends] - values[starts], ends - starts + 1)
        inner = np.flatnonzero(~first & ~last & (span > 0))
        gap = np.zeros(n)
        gap[inner] = (values[inner + 1] - values[inner - 1]) / (n_obj * span[inner])
        gap[first | last] = np.inf
        distance[order] += gap
    return distance


def select_nsga2(loss: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Returns NSGA-II's survivors: whole fronts in order, the last one cut by crowding.

    As DEAP's `selNSGA2`: the partial front is sorted by decreasing crowding distance with
    ties in index order.

    Args:
        loss: (N, 2) objective values to minimise.
        k: survivors, k <= N.

    Returns:
        (index (k,), their ranks (k,), their crowding distances (k,)); index lists the
        survivors front by front.
    """
    ranks = non_dominated_ranks(loss)
    distance = crowding_distance(loss, ranks)
    order = np.argsort(ranks, kind="stable")
    cut_rank = ranks[order[k - 1]]
    full = order[ranks[order] < cut_rank]
    partial = order[ranks[order] == cut_rank]
    partial = partial[np.argsort(-distance[partial], kind="stable")][: k - full.size]
    index = np.concatenate([full, partial])
    return index, ranks[index], distance[index]


def hypervolume_2d(loss: np.ndarray, reference: tuple[float, float]) -> float:
    """Returns the area dominated by `loss` and bounded by `reference` (minimising).

    Points not strictly better than the reference in both objectives add nothing.

    Args:
        loss: (N, 2) objective values.
        reference: the (f0, f1) corner.
    """
    ref0, ref1 = reference
    inside = loss[(loss[:, 0] < ref0) & (loss[:, 1] < ref1)]
    if inside.shape[0] == 0:
        return 0.0
    inside = inside[np.lexsort((inside[:, 1], inside[:, 0]))]
    best_f1 = np.minimum.accumulate(inside[:, 1])
    next_f0 = np.append(inside[1:, 0], ref0)
    return float(np.sum((next_f0 - inside[:, 0]) * (ref1 - best_f1)))
