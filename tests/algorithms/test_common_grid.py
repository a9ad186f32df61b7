"""The common grid (every told genome on the MAP-LIS grid) and path diversity."""

from __future__ import annotations

import numpy as np
import pytest

from linkevo.algorithms import scalar_loss
from linkevo.algorithms.scoring import QD_OFFSETS
from linkevo.sim.linkage.descriptors import DESCRIPTOR_SPACES, bin_descriptors, cell_index
from linkevo.sim.linkage.path_diversity import path_diversity
from tests.algorithms.test_optimizers import make, synthetic_evaluation


@pytest.mark.parametrize("approach", ["EA", "NSGA2", "MAP-WH", "MAP-LIS", "MAP-ST", "RANDOM"])
def test_common_grid_holds_the_best_loss_of_every_told_genome(approach: str) -> None:
    """Recomputed from scratch: every told genome's MAP-LIS cell and scalar loss."""
    opt = make(approach, batch_size=300, initial_sigma=0.1)
    space = DESCRIPTOR_SPACES["MAP-LIS"]
    best: dict[int, float] = {}
    history = []
    for _ in range(6):
        genomes = opt.ask()
        evaluation = synthetic_evaluation(genomes, 2 if approach == "NSGA2" else 1)
        opt.tell(genomes, evaluation)
        loss = scalar_loss(evaluation.loss, evaluation.error, evaluation.angle_error, "Fp")
        cells = cell_index(bin_descriptors(evaluation.descriptors["MAP-LIS"], space), space)
        for cell, value in zip(cells, loss, strict=True):
            best[int(cell)] = min(best.get(int(cell), np.inf), float(value))
        history.append(opt.metrics())
    last = history[-1]
    assert last["common_coverage"] == len(best) / space.n_cells
    expected = sum(max(QD_OFFSETS["Fp"] - v, 0.0) for v in best.values())
    assert last["common_qd_score"] == pytest.approx(expected, rel=1e-12)
    coverage = [m["common_coverage"] for m in history]
    assert coverage == sorted(coverage)  # cumulative: it never falls
    if approach in ("MAP-LIS", "RANDOM"):  # their own grid is the common one
        assert last["common_coverage"] == last["coverage"]
        assert last["common_qd_score"] == pytest.approx(last["qd_score"], rel=1e-12)
    if approach in ("EA", "NSGA2"):  # the population's cells are a few of those ever seen
        assert last["common_coverage"] > 3 * last["coverage"]


def circle(n: int, r: float = 1.0, x0: float = 0.0, phase: int = 0) -> np.ndarray:
    angles = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.roll(np.c_[x0 + r * np.cos(angles), r * np.sin(angles)], phase, axis=0)


def test_path_diversity_measures_shape_alone() -> None:
    a = circle(24)
    same = [a, circle(24, r=7.0, x0=30.0, phase=5), circle(24, r=0.5, phase=11)]
    x = np.stack([p[:, 0] for p in same])
    y = np.stack([p[:, 1] for p in same])
    assert path_diversity(x, y, np.arange(3.0)) == pytest.approx(0.0, abs=1e-12)
    line = np.c_[np.linspace(-1, 1, 24), np.zeros(24)]
    x2, y2 = np.vstack([x[:1], line[None, :, 0]]), np.vstack([y[:1], line[None, :, 1]])
    assert path_diversity(x2, y2, np.arange(2.0)) > 0.5
    # A foot that does not move is a point, whatever its rounding noise: no shape at all.
    still = 3.0 + np.random.default_rng(1).normal(0, 1e-6, (2, 2, 24))
    assert path_diversity(still[:, 0], still[:, 1], np.arange(2.0)) == 0.0


def test_path_diversity_takes_the_best_complete_paths() -> None:
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(5, 16)), rng.normal(size=(5, 16))
    x[1:3], y[1:3] = x[0], y[0]  # three copies of one shape, the best three
    loss = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    assert path_diversity(x, y, loss, k=3) == pytest.approx(0.0, abs=1e-12)
    assert path_diversity(x, y, loss, k=5) > 0.3
    x[1, 4] = np.nan  # an incomplete path is left out: the next best takes its place
    assert path_diversity(x, y, loss, k=3) > 0.3
    assert np.isnan(path_diversity(x[:1], y[:1], loss[:1]))
