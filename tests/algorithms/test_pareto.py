"""NSGA-II sort, crowding, selection and hypervolume against brute-force computations."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from deap import base, creator, tools

from linkevo.algorithms.pareto import (
    crowding_distance,
    hypervolume_2d,
    non_dominated_ranks,
    select_nsga2,
)


def brute_force_ranks(loss: np.ndarray) -> np.ndarray:
    """Peels fronts with an O(N^2) dominance matrix."""
    le = np.all(loss[:, None, :] <= loss[None, :, :], axis=2)
    lt = np.any(loss[:, None, :] < loss[None, :, :], axis=2)
    dominates = le & lt  # [i, j]: i dominates j
    ranks = np.full(loss.shape[0], -1)
    front = 0
    while (ranks < 0).any():
        remaining = ranks < 0
        dominated = (dominates & remaining[:, None]).any(axis=0)
        ranks[remaining & ~dominated] = front
        front += 1
    return ranks


def brute_force_crowding(loss: np.ndarray, ranks: np.ndarray) -> np.ndarray:
    """DEAP's assignCrowdingDist, in plain Python, front by front in index order."""
    distance = np.zeros(loss.shape[0])
    n_obj = loss.shape[1]
    for r in np.unique(ranks):
        crowd = [(tuple(loss[i]), int(i)) for i in np.flatnonzero(ranks == r)]
        for m in range(n_obj):
            crowd.sort(key=lambda e, m=m: e[0][m])
            distance[crowd[0][1]] = np.inf
            distance[crowd[-1][1]] = np.inf
            if crowd[-1][0][m] == crowd[0][0][m]:
                continue
            norm = n_obj * (crowd[-1][0][m] - crowd[0][0][m])
            for prev, cur, nxt in zip(crowd[:-2], crowd[1:-1], crowd[2:], strict=True):
                distance[cur[1]] += (nxt[0][m] - prev[0][m]) / norm
    return distance


def random_losses(seed: int, n: int, discrete: bool) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if discrete:  # many ties and exact duplicates
        return rng.integers(0, 12, size=(n, 2)).astype(float)
    return rng.random((n, 2)) * np.array([3.0, 1.0])


@pytest.mark.parametrize("discrete", [False, True])
@pytest.mark.parametrize("seed", range(4))
def test_ranks_equal_brute_force(seed: int, discrete: bool) -> None:
    loss = random_losses(seed, 400, discrete)
    np.testing.assert_array_equal(non_dominated_ranks(loss), brute_force_ranks(loss))


def test_ranks_equal_deap_sort() -> None:
    loss = random_losses(9, 300, discrete=True)
    if not hasattr(creator, "FitnessMin2"):
        creator.create("FitnessMin2", base.Fitness, weights=(-1.0, -1.0))
    individuals = []
    for i, row in enumerate(loss):
        ind = creator.FitnessMin2()
        ind.values = tuple(row)
        individuals.append(type("Ind", (), {"fitness": ind, "index": i})())
    fronts = tools.sortNondominated(individuals, len(individuals))
    expected = np.empty(len(loss), dtype=np.int64)
    for r, front in enumerate(fronts):
        for ind in front:
            expected[ind.index] = r
    np.testing.assert_array_equal(non_dominated_ranks(loss), expected)


@pytest.mark.parametrize("discrete", [False, True])
@pytest.mark.parametrize("seed", range(4))
def test_crowding_equals_brute_force(seed: int, discrete: bool) -> None:
    loss = random_losses(seed, 300, discrete)
    ranks = brute_force_ranks(loss)
    np.testing.assert_allclose(
        crowding_distance(loss, ranks), brute_force_crowding(loss, ranks), rtol=1e-12
    )


@pytest.mark.parametrize("seed", range(3))
def test_selection_takes_whole_fronts_then_most_crowded(seed: int) -> None:
    loss = random_losses(seed, 500, discrete=False)
    expected_ranks = brute_force_ranks(loss)
    k = np.count_nonzero(expected_ranks < 5) + np.count_nonzero(expected_ranks == 5) // 2
    index, ranks, crowd = select_nsga2(loss, k)
    assert index.shape == (k,) and np.unique(index).size == k
    np.testing.assert_array_equal(ranks, expected_ranks[index])
    cut = ranks.max()
    assert np.all(np.isin(np.flatnonzero(expected_ranks < cut), index))
    left_out = np.setdiff1d(np.flatnonzero(expected_ranks == cut), index)
    expected_crowd = brute_force_crowding(loss, expected_ranks)
    assert left_out.size > 0
    assert expected_crowd[index[ranks == cut]].min() >= expected_crowd[left_out].max()
    np.testing.assert_allclose(crowd, expected_crowd[index])


def brute_force_hypervolume(loss: np.ndarray, ref: tuple[float, float]) -> float:
    """Integrates the dominated height over every interval between distinct f0 values."""
    xs = sorted({x for x in loss[:, 0] if x < ref[0]} | {ref[0]})
    area = 0.0
    for left, right in itertools.pairwise(xs):
        heights = [ref[1] - y for x, y in loss if x <= left and y < ref[1]]
        area += (right - left) * max(heights, default=0.0)
    return area


@pytest.mark.parametrize("discrete", [False, True])
def test_hypervolume_equals_brute_force(discrete: bool) -> None:
    loss = random_losses(3, 200, discrete)
    ref = (2.5, 0.9) if not discrete else (10.0, 9.0)
    assert hypervolume_2d(loss, ref) == pytest.approx(brute_force_hypervolume(loss, ref))


def test_hypervolume_of_one_point_and_of_points_outside() -> None:
    assert hypervolume_2d(np.array([[1.0, 2.0]]), (3.0, 5.0)) == pytest.approx(6.0)
    assert hypervolume_2d(np.array([[4.0, 2.0], [1.0, 5.0]]), (3.0, 5.0)) == 0.0
