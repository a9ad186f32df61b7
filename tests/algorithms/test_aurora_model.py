"""Tests of the AURORA path autoencoder, its training loops and its path inputs."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from linkevo.algorithms.aurora_model import PathAutoencoder
from linkevo.algorithms.aurora_paths import prepare_paths, valid_rows
from tests.helpers.aurora_reference import reference_module, train_reference

N_ANGLES = 40


def path_family(n: int, seed: int, n_angles: int = N_ANGLES) -> tuple[np.ndarray, np.ndarray]:
    """Returns n synthetic foot paths (n, A) x2: ellipses and 'D' shapes of varied size,
    position and phase, the kind of closed curves a crank-driven foot traces."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 2 * np.pi, n_angles, endpoint=False)[None, :] + rng.uniform(
        0, 2 * np.pi, (n, 1)
    )
    width, height = rng.uniform(3, 20, (n, 1)), rng.uniform(1, 8, (n, 1))
    cx, cy = rng.uniform(-10, 10, (n, 1)), rng.uniform(-15, 0, (n, 1))
    flat = rng.random((n, 1)) < 0.5
    y = np.where(flat, np.maximum(np.sin(t), -0.3), np.sin(t))
    return cx + width * np.cos(t), cy + height * y


@pytest.mark.parametrize(("representation", "ratio"), [("raw", 0.75), ("centred", 0.4)])
def test_reconstruction_loss_falls_on_path_families(representation: str, ratio: float) -> None:
    # Raw paths also carry their position (about +-15 units), which four codes must
    # share with the shape, so they fall less far in 60 epochs.
    x = prepare_paths(*path_family(256, seed=0), representation)
    model = PathAutoencoder(seed=0)
    result = model.train(x, epochs=60, batch_size=32, learning_rate=0.03, seed=1)
    assert result.n_samples == 256
    assert result.n_steps == 60 * 8
    assert result.final_loss < ratio * result.initial_loss
    held_out = prepare_paths(*path_family(64, seed=1), representation)
    assert model.loss(held_out) < ratio * PathAutoencoder(seed=0).loss(held_out)


def test_encodings_lie_in_the_unit_hypercube() -> None:
    rng = np.random.default_rng(2)
    x = np.concatenate(
        [rng.normal(0, 1e3, (100, 80)), np.zeros((1, 80)), prepare_paths(*path_family(50, 3))]
    ).astype(np.float32)
    model = PathAutoencoder(seed=4)
    model.train(x[-50:], epochs=5, batch_size=16, learning_rate=0.01, seed=5)
    codes = model.encode(x)
    assert codes.shape == (151, 4)
    assert codes.dtype == np.float64
    assert np.all((codes >= 0.0) & (codes <= 1.0))
    assert codes[-50:].std(axis=0).max() > 0.0


@pytest.mark.parametrize(
    ("loop", "n_angles", "batch_size"),
    [("compiled", 40, 32), ("compiled", 39, 20), ("compiled", 40, 7), ("torch", 40, 32)],
)
def test_hand_written_loops_match_plain_autograd_training(loop, n_angles, batch_size) -> None:
    """Both loops, with widths and batches that leave remainder rows and padded lanes."""
    x = prepare_paths(*path_family(100, seed=6, n_angles=n_angles), "centred")
    fused = PathAutoencoder(n_inputs=2 * n_angles, seed=7, loop=loop)
    plain = reference_module(fused.state_dict())
    fused.train(x, epochs=4, batch_size=batch_size, learning_rate=0.01, seed=8)
    train_reference(plain, x, epochs=4, batch_size=batch_size, learning_rate=0.01, seed=8)
    trained = reference_module(fused.state_dict())
    for mine, theirs in zip(trained.parameters(), plain.parameters(), strict=True):
        torch.testing.assert_close(mine, theirs, atol=1e-5, rtol=1e-4)
    with torch.no_grad():
        np.testing.assert_allclose(
            plain(torch.as_tensor(x)).numpy(), fused.reconstruct(x), atol=1e-4
        )


def test_training_is_reproducible_from_its_seeds() -> None:
    x = prepare_paths(*path_family(64, seed=9))
    a, b, c = PathAutoencoder(seed=1), PathAutoencoder(seed=1), PathAutoencoder(seed=1)
    for model, shuffle in ((a, 2), (b, 2), (c, 3)):
        model.train(x, epochs=3, batch_size=16, learning_rate=0.01, seed=shuffle)
    assert np.array_equal(a.encode(x), b.encode(x))
    assert not np.array_equal(a.encode(x), c.encode(x))
    assert not np.array_equal(PathAutoencoder(seed=1).encode(x), PathAutoencoder(seed=2).encode(x))


def test_state_dict_round_trips_through_torch_save(tmp_path) -> None:
    x = prepare_paths(*path_family(64, seed=10))
    model = PathAutoencoder(seed=11)
    model.train(x, epochs=2, batch_size=16, learning_rate=0.01, seed=12)
    torch.save(model.state_dict(), tmp_path / "encoder.pt")
    restored = PathAutoencoder(seed=99)
    restored.load_state_dict(torch.load(tmp_path / "encoder.pt", weights_only=True))
    assert np.array_equal(restored.encode(x), model.encode(x))
    # The Adagrad sums travel too, so further training continues identically.
    for m in (model, restored):
        m.train(x, epochs=2, batch_size=16, learning_rate=0.01, seed=13)
    assert np.array_equal(restored.reconstruct(x), model.reconstruct(x))


def test_load_state_dict_names_a_misshapen_entry() -> None:
    state = PathAutoencoder(seed=0).state_dict()
    state["layers.3.weight"] = torch.zeros(3, 3)
    with pytest.raises(ValueError, match=r"layers\.3\.weight.*\(16, 32\)"):
        PathAutoencoder(seed=0).load_state_dict(state)
    del state["adagrad_sum"]
    state["layers.3.weight"] = torch.zeros(16, 32)
    with pytest.raises(ValueError, match=r"adagrad_sum.*missing"):
        PathAutoencoder(seed=0).load_state_dict(state)


def test_train_rejects_bad_input_before_any_step() -> None:
    model = PathAutoencoder(seed=0)
    before = model.encode(np.zeros((1, 80), np.float32))
    with pytest.raises(ValueError, match=r"\(N, 80\).*\(5, 40\)"):
        model.train(
            np.zeros((5, 40), np.float32), epochs=1, batch_size=4, learning_rate=0.1, seed=0
        )
    with pytest.raises(ValueError, match="at least one path"):
        model.train(
            np.zeros((0, 80), np.float32), epochs=1, batch_size=4, learning_rate=0.1, seed=0
        )
    with pytest.raises(ValueError, match="batch_size >= 1"):
        model.train(np.ones((5, 80), np.float32), epochs=1, batch_size=0, learning_rate=0.1, seed=0)
    assert np.array_equal(model.encode(np.zeros((1, 80), np.float32)), before)


def test_raw_paths_drop_failed_angles_and_pad_with_zeros() -> None:
    foot_x = np.array([[1.0, np.nan, 3.0, 4.0]])
    foot_y = np.array([[5.0, np.nan, 7.0, 8.0]])
    out = prepare_paths(foot_x, foot_y, "raw")
    assert out.dtype == np.float32
    np.testing.assert_array_equal(out, [[1, 5, 3, 7, 4, 8, 0, 0]])


def test_centred_paths_sit_on_their_centroid_and_scale() -> None:
    foot_x = np.array([[10.0, 13.0, np.nan, 16.0]])
    foot_y = np.array([[-2.0, 4.0, np.nan, 1.0]])
    out = prepare_paths(foot_x, foot_y, "centred", scale=3.0)
    np.testing.assert_allclose(out, [[-1, -1, 0, 1, 1, 0, 0, 0]], atol=1e-6)


def test_minmax_paths_span_the_unit_square() -> None:
    foot_x, foot_y = path_family(20, seed=14)
    foot_x[:, 5] = np.nan
    foot_y[:, 5] = np.nan
    out = prepare_paths(foot_x, foot_y, "minmax").reshape(20, 40, 2)[:, :39]
    np.testing.assert_allclose(out.min(axis=1), 0.0, atol=1e-6)
    np.testing.assert_allclose(out.max(axis=1), 1.0, atol=1e-6)
    assert np.all(prepare_paths(foot_x, foot_y, "minmax").reshape(20, 40, 2)[:, 39] == 0.0)


def test_prepare_paths_rejects_unknown_representation_and_bad_scale() -> None:
    x, y = path_family(2, seed=15)
    with pytest.raises(ValueError, match=r"'polar'.*raw, centred, minmax"):
        prepare_paths(x, y, "polar")
    with pytest.raises(ValueError, match="scale must be > 0"):
        prepare_paths(x, y, "centred", scale=0.0)
    with pytest.raises(ValueError, match=r"\(2, 40\) and \(2, 39\)"):
        prepare_paths(x, y[:, :39])


def test_valid_rows_are_those_without_failed_angles() -> None:
    np.testing.assert_array_equal(valid_rows(np.array([0, 3, 0, 1, 0])), [0, 2, 4])
