"""Mutation statistics (spec §6): paper additive self-adaptive, legacy two-sigma reset."""

from __future__ import annotations

import numpy as np
import pytest

from linkevo.algorithms.mutation import bounce_back, initial_sigma, mutate
from linkevo.sim.linkage.genome import LENGTH_GENES, N_GENES

OTHER_GENES = np.setdiff1d(np.arange(N_GENES), LENGTH_GENES)


def test_bounce_back_folds_into_unit_interval() -> None:
    values = np.array([0.25, 1.2, -0.3, 2.5, -1.2, 3.9, 1.0, -2.0])
    expected = np.array([0.25, 0.8, 0.3, 0.5, 0.8, 0.1, np.nextafter(1.0, 0.0), 0.0])
    np.testing.assert_allclose(bounce_back(values), expected, atol=1e-12)
    wild = np.random.default_rng(0).normal(0.0, 50.0, 100_000)
    folded = bounce_back(wild)
    assert folded.min() >= 0.0 and folded.max() < 1.0


def test_paper_mutation_moves_length_genes_always_others_one_in_five() -> None:
    rng = np.random.default_rng(1)
    n = 20_000
    parents = rng.random((n, N_GENES))
    sigma = np.full((n, 1), 0.05)
    children, child_sigma = mutate(parents, sigma, rng, "paper")
    moved = children != parents
    assert moved[:, LENGTH_GENES].all()
    assert moved[:, OTHER_GENES].mean() == pytest.approx(0.2, abs=0.005)
    assert (child_sigma != sigma).mean() == pytest.approx(0.2, abs=0.01)
    assert children.min() >= 0.0 and children.max() < 1.0
    assert child_sigma.min() >= 0.0 and child_sigma.max() < 1.0
    step = np.abs(children - parents)[:, LENGTH_GENES]
    assert np.median(step) < 0.1  # additive noise around the parent, not a reset


def test_paper_mutation_adds_noise_scaled_by_the_new_sigma() -> None:
    rng = np.random.default_rng(2)
    n = 50_000
    parents = np.full((n, N_GENES), 0.5)
    children, child_sigma = mutate(parents, np.full((n, 1), 0.02), rng, "paper")
    kept_sigma = child_sigma[:, 0] == 0.02
    noise = children[kept_sigma][:, LENGTH_GENES] - 0.5
    assert noise.std() == pytest.approx(0.02, rel=0.02)
    assert abs(noise.mean()) < 1e-3


def test_legacy_mutation_resets_genes_near_zero() -> None:
    rng = np.random.default_rng(3)
    n = 20_000
    parents = np.full((n, N_GENES), 0.9)
    sigma = np.tile([0.05, 0.03], (n, 1))
    children, child_sigma = mutate(parents, sigma, rng, "legacy")
    assert child_sigma.shape == (n, 2)
    assert (child_sigma != sigma).mean() == pytest.approx(0.2, abs=0.01)
    unchanged_sigma = (child_sigma == sigma).all(axis=1)
    # Replaced by |N(0, sigma)|, not 0.9 + noise.
    assert (children[unchanged_sigma][:, LENGTH_GENES] < 0.5).all()
    reset_rows = (children[:, OTHER_GENES] != 0.9).all(axis=1)
    untouched_rows = (children[:, OTHER_GENES] == 0.9).all(axis=1)
    assert (reset_rows | untouched_rows).all()  # all 56 genes or only the 15 length genes
    assert reset_rows.mean() == pytest.approx(0.2, abs=0.01)
    length_values = children[unchanged_sigma][:, LENGTH_GENES]
    assert length_values.mean() == pytest.approx(0.03 * np.sqrt(2 / np.pi), rel=0.02)
    assert children.min() >= 0.0 and children.max() < 1.0


def test_same_seed_same_children() -> None:
    parents = np.random.default_rng(4).random((100, N_GENES))
    sigma = np.full((100, 1), 0.1)
    a = mutate(parents, sigma, np.random.default_rng(7), "paper")
    b = mutate(parents, sigma, np.random.default_rng(7), "paper")
    c = mutate(parents, sigma, np.random.default_rng(8), "paper")
    np.testing.assert_array_equal(a[0], b[0])
    assert not np.array_equal(a[0], c[0])


def test_sigma_shape_must_match_mode() -> None:
    parents = np.zeros((3, N_GENES))
    with pytest.raises(ValueError, match=r"sigma must have shape \(3, 2\)"):
        mutate(parents, np.zeros((3, 1)), np.random.default_rng(0), "legacy")
    with pytest.raises(ValueError, match="mode must be 'paper' or 'legacy', got 'fast'"):
        initial_sigma(np.random.default_rng(0), 3, "fast")
