"""Tournament selection picks the best of three aspirants."""

from __future__ import annotations

import numpy as np

from linkevo.algorithms.selection import tournament


def test_tournament_winner_is_best_of_its_three_aspirants() -> None:
    loss = np.random.default_rng(0).random(50)
    winners = tournament(loss, 1000, np.random.default_rng(11))
    aspirants = np.random.default_rng(11).integers(0, 50, size=(1000, 3))
    assert (winners[:, None] == aspirants).any(axis=1).all()
    np.testing.assert_array_equal(loss[winners], loss[aspirants].min(axis=1))


def test_tournament_favours_low_losses() -> None:
    loss = np.arange(1000.0)
    winners = tournament(loss, 100_000, np.random.default_rng(1))
    # The best of three uniform ranks has mean N/4.
    assert abs(winners.mean() / 1000 - 0.25) < 0.01
    assert np.count_nonzero(winners == 999) < 5
