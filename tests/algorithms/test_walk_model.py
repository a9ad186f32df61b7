"""The learned walk model (`algorithms.walk_model`) and its inputs (`sim.robot.walk_features`):
what it learns, what it keeps, what it refuses."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.stats import spearmanr

from linkevo.algorithms.walk_model import WalkData, WalkModel
from linkevo.sim.robot.walk_features import FEATURE_NAMES, walk_features
from linkevo.sim.robot.walk_rows import FLOOR_ORDER


def synthetic(n: int, seed: int) -> WalkData:
    """Walks whose distance rises with the first feature and whose robot breaks when the
    second is high: a relation a model must find."""
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, 6)).astype(np.float32)
    distance = np.stack([40 + 25 * x[:, 0], 30 + 20 * x[:, 0] - 5 * x[:, 2]], axis=1)
    breaks = (x[:, 1:2] + 0.3 * rng.normal(size=(n, 1)) > 0.8).astype(float).repeat(2, axis=1)
    return WalkData(x, np.where(breaks > 0, np.nan, distance), breaks)


def test_it_ranks_unseen_walks_and_tells_breaks_apart():
    model = WalkModel(6).fit(synthetic(600, 0), seed=1)
    test = synthetic(300, 9)
    prediction = model.predict(test.features)
    for k in range(len(FLOOR_ORDER)):
        sound = np.isfinite(test.distance[:, k])
        rho = spearmanr(prediction.distance[sound, k], test.distance[sound, k]).statistic
        assert rho > 0.9, FLOOR_ORDER[k]
        broke = test.breaks[:, k] > 0
        assert prediction.p_break[broke, k].mean() > prediction.p_break[~broke, k].mean() + 0.4
    assert (prediction.spread >= 0).all() and prediction.spread.shape == (300, 2)


def test_the_same_seed_fits_the_same_model():
    data = synthetic(200, 3)
    one = WalkModel(6).fit(data, seed=4).predict(data.features[:20])
    two = WalkModel(6).fit(data, seed=4).predict(data.features[:20])
    np.testing.assert_array_equal(one.distance, two.distance)


def test_weights_round_trip_through_torch_save_weights_only(tmp_path):
    data = synthetic(200, 5)
    model = WalkModel(6).fit(data, seed=0)
    torch.save(model.state_dict(), tmp_path / "walk_model.pt")
    restored = WalkModel.from_state_dict(torch.load(tmp_path / "walk_model.pt", weights_only=True))
    np.testing.assert_array_equal(
        restored.predict(data.features).distance, model.predict(data.features).distance
    )


def test_a_state_that_is_not_a_walk_models_is_refused():
    with pytest.raises(ValueError, match="not a walk model's state"):
        WalkModel.from_state_dict({"encoder.weight": torch.zeros(3)})
    with pytest.raises(ValueError, match="at least one walk"):
        WalkModel(6).fit(WalkData(np.zeros((0, 6)), np.zeros((0, 2)), np.zeros((0, 2))))


def test_features_are_finite_and_the_stance_moves_forwards():
    genomes = np.random.default_rng(0).random((300, 56))
    features = walk_features(genomes)
    assert features.shape == (300, len(FEATURE_NAMES)) and np.isfinite(features).all()
    assert walk_features(np.zeros((0, 56))).shape == (0, len(FEATURE_NAMES))
    # The foot path is mirrored so that its lower half moves towards +x, as the robot
    # mounts a leg: among the linkages that turn, the stance's mean step is forwards.
    x = features[:, : FEATURE_NAMES.index("foot_y_0")]
    y = features[:, FEATURE_NAMES.index("foot_y_0") : FEATURE_NAMES.index("path_width")]
    turns = features[:, FEATURE_NAMES.index("assembled_share")] == 1.0
    step = np.diff(x, axis=1, append=x[:, :1])
    low = y <= ((y.min(axis=1) + y.max(axis=1)) / 2)[:, None]
    assert turns.sum() > 10
    assert ((step * low).sum(axis=1)[turns] >= 0).all()
