"""Tests of AuroraMapElites (MAP-AU): training on valid paths, re-indexing, state, resume."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
import torch

from linkevo.algorithms.aurora import AuroraMapElites, AuroraSettings
from linkevo.algorithms.aurora_model import PathAutoencoder
from linkevo.algorithms.aurora_paths import prepare_paths
from linkevo.algorithms.factory import make_optimizer
from linkevo.sim import evaluate
from linkevo.sim.linkage.evaluation import Evaluation

SMALL = {
    "initial_epochs": 4,
    "retrain_epochs": 3,
    "retrain_period": 2,
    "ae_batch_size": 64,
    "learning_rate": 0.01,
}
"""A schedule small enough for tests; the paper's numbers are the defaults."""


def make(seed: int = 3, batch_size: int = 400, **options: object) -> AuroraMapElites:
    """Returns a small MAP-AU optimizer on F_p."""
    return AuroraMapElites(
        fitness="Fp", batch_size=batch_size, mode="paper", seed=seed, **(SMALL | options)
    )


def step(optimizer: AuroraMapElites) -> tuple[np.ndarray, Evaluation]:
    """Runs one ask -> evaluate -> tell round; returns the genomes and their evaluation."""
    genomes = optimizer.ask()
    evaluation = evaluate(genomes, "Fp", "paper")
    optimizer.tell(genomes, evaluation)
    return genomes, evaluation


def test_make_optimizer_builds_map_au_with_paper_defaults() -> None:
    optimizer = make_optimizer("MAP-AU", fitness="Fp", batch_size=10, mode="paper", seed=0)
    assert isinstance(optimizer, AuroraMapElites)
    assert optimizer.aurora == AuroraSettings()
    assert (optimizer.aurora.initial_epochs, optimizer.aurora.retrain_epochs) == (3000, 1000)
    assert (optimizer.aurora.ae_batch_size, optimizer.aurora.learning_rate) == (32, 0.001)
    assert optimizer.aurora.retrain_period == 10
    assert optimizer.archive.n_cells == 10_000


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"epochs": 5}, r"unknown option\(s\) 'epochs' for MAP-AU; allowed: .*initial_epochs"),
        ({"retrain_period": 0}, r"retrain_period must be an integer >= 1, got 0"),
        ({"learning_rate": -1.0}, r"learning_rate must be a number > 0, got -1.0"),
        ({"representation": "polar"}, r"'polar'; allowed: raw, centred, minmax"),
        ({"device": "tpu"}, r"unknown device 'tpu'; allowed: auto, cpu, cuda"),
        ({"initial_epochs": 1.5}, r"initial_epochs must be an integer >= 0, got 1.5"),
    ],
)
def test_bad_settings_are_refused_by_name(options: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        make_optimizer("MAP-AU", fitness="Fp", batch_size=10, mode="paper", seed=0, **options)


def test_initial_training_sees_exactly_the_valid_paths() -> None:
    optimizer = make(seed=5)
    _, evaluation = step(optimizer)
    valid = evaluation.error == 0
    assert 0 < valid.sum() < len(valid)
    metrics = optimizer.metrics()
    assert metrics["train_paths"] == valid.sum()
    assert np.isnan(metrics["elites_dropped"])
    # Training a fresh encoder on the valid rows alone, with the optimizer's seeds,
    # gives the very same weights: no invalid path reached training.
    twin = PathAutoencoder(seed=optimizer.training_seed(-1))
    paths = prepare_paths(evaluation.foot_x[valid], evaluation.foot_y[valid])
    result = twin.train(
        paths, epochs=4, batch_size=64, learning_rate=0.01, seed=optimizer.training_seed(0)
    )
    assert metrics["recon_loss"] == pytest.approx(result.final_loss, rel=1e-12)
    for name, tensor in twin.state_dict().items():
        assert torch.equal(tensor, optimizer.torch_state()[name]), name


def test_retraining_uses_only_valid_elites_and_reindexes_every_elite() -> None:
    optimizer = make(seed=6)
    for _ in range(3):  # the initial batch, then children batches 1 and 2 (2 % period == 0)
        step(optimizer)
    assert optimizer.trainings == 2
    elites = optimizer.archive.elites
    assert elites is not None
    metrics = optimizer.metrics()
    valid = elites.error == 0
    assert 0 < valid.sum() < len(elites)
    # Training saw the valid elites before re-indexing, some of which it then dropped.
    assert valid.sum() <= metrics["train_paths"] <= valid.sum() + metrics["elites_dropped"]
    assert metrics["elites_dropped"] > 0
    # Every elite, invalid ones included, sits where the new encoder puts it, alone.
    desc = optimizer.encode(elites.foot_x, elites.foot_y)
    np.testing.assert_array_equal(elites.desc, desc)
    np.testing.assert_array_equal(optimizer.archive.cells, optimizer.archive.cell_index(desc))
    assert np.unique(optimizer.archive.cells).size == len(elites)
    assert np.all((desc >= 0.0) & (desc <= 1.0))


def test_reindexing_keeps_the_best_elite_and_counts_the_dropped() -> None:
    optimizer = make(seed=7)
    step(optimizer)
    before_genome, before_loss = optimizer.best()
    n_before = len(optimizer.archive)
    # Squeeze every elite into two cells: exactly two survive, the best among them.
    desc = np.zeros((n_before, 4))
    desc[: n_before // 2] = 0.95
    dropped = optimizer.reindex(desc)
    assert dropped == n_before - 2
    assert len(optimizer.archive) == 2
    assert np.unique(optimizer.archive.cells).size == 2
    genome, loss = optimizer.best()
    assert loss == before_loss
    np.testing.assert_array_equal(genome, before_genome)


def test_best_elite_survives_every_retraining() -> None:
    optimizer = make(seed=8, retrain_period=1)
    step(optimizer)
    for _ in range(3):
        best_genome, best_loss = optimizer.best()
        step(optimizer)
        assert not np.isnan(optimizer.metrics()["elites_dropped"])
        elites = optimizer.archive.elites
        assert elites is not None
        loss = optimizer.best()[1]
        assert loss <= best_loss
        # Only a strictly better child in the same cell may displace the best elite.
        assert loss < best_loss or np.any(np.all(elites.genome == best_genome, axis=1))
        assert np.unique(optimizer.archive.cells).size == len(elites)


def test_metrics_report_training_only_when_it_happens() -> None:
    optimizer = make(seed=9, retrain_period=3)
    reports = []
    for _ in range(4):
        step(optimizer)
        reports.append(optimizer.metrics())
    trained = [r["train_paths"] > 0 for r in reports]
    assert trained == [True, False, False, True]
    for report, did in zip(reports, trained, strict=True):
        assert np.isnan(report["recon_loss"]) != did
        assert report["recon_loss"] > 0 if did else report["train_paths"] == 0
    assert np.isnan(reports[0]["elites_dropped"])
    assert not np.isnan(reports[3]["elites_dropped"])


def test_a_trial_is_reproducible_from_its_seed() -> None:
    a, b, c = make(seed=10), make(seed=10), make(seed=11)
    for optimizer in (a, b, c):
        for _ in range(3):
            step(optimizer)
    np.testing.assert_array_equal(a.archive.cells, b.archive.cells)
    np.testing.assert_array_equal(a.archive.elites.genome, b.archive.elites.genome)
    for name, tensor in a.torch_state().items():
        assert torch.equal(tensor, b.torch_state()[name])
    assert not torch.equal(a.torch_state()["layers.0.weight"], c.torch_state()["layers.0.weight"])


def test_checkpoint_then_resume_gives_the_same_encoder_and_repertoire(tmp_path) -> None:
    straight = make(seed=12)
    for _ in range(5):
        step(straight)

    first = make(seed=12)
    for _ in range(3):
        step(first)
    np.savez(tmp_path / "state.npz", **first.state_dict())
    torch.save(first.torch_state(), tmp_path / "encoder.pt")
    with np.load(tmp_path / "state.npz") as saved:
        state = dict(saved)
    resumed = make(seed=12)
    resumed.load_state_dict(state)
    encoder = torch.load(tmp_path / "encoder.pt", weights_only=True)
    for name, tensor in encoder.items():
        assert torch.equal(tensor, resumed.torch_state()[name]), name
    assert resumed.metrics() == pytest.approx(first.metrics(), nan_ok=True)
    for _ in range(2):
        step(resumed)

    assert resumed.trainings == straight.trainings == 3
    for name, tensor in straight.torch_state().items():
        assert torch.equal(tensor, resumed.torch_state()[name]), name
    np.testing.assert_array_equal(resumed.archive.cells, straight.archive.cells)
    for key, value in straight.state_dict().items():
        if key != "optimizer.settings":
            np.testing.assert_array_equal(resumed.state_dict()[key], value, err_msg=key)
    assert resumed.metrics() == pytest.approx(straight.metrics(), nan_ok=True)


def test_saved_encoder_alone_restores_the_encodings(tmp_path) -> None:
    optimizer = make(seed=13)
    _, evaluation = step(optimizer)
    torch.save(optimizer.torch_state(), tmp_path / "encoder.pt")
    fresh = make(seed=99)
    fresh.load_torch_state(torch.load(tmp_path / "encoder.pt", weights_only=True))
    np.testing.assert_array_equal(
        fresh.encode(evaluation.foot_x, evaluation.foot_y),
        optimizer.encode(evaluation.foot_x, evaluation.foot_y),
    )


def test_resume_refuses_a_state_from_a_different_schedule() -> None:
    optimizer = make(seed=14)
    step(optimizer)
    other = make(seed=14, retrain_epochs=7)
    with pytest.raises(ValueError, match="differing settings: aurora"):
        other.load_state_dict(optimizer.state_dict())


def test_a_batch_without_valid_paths_skips_training() -> None:
    optimizer = make(seed=15, batch_size=50)
    genomes = optimizer.ask()
    evaluation = evaluate(genomes, "Fp", "paper")
    broken = replace(evaluation, error=np.maximum(evaluation.error, 1))
    optimizer.tell(genomes, broken)
    assert optimizer.trainings == 0
    assert optimizer.metrics()["train_paths"] == 0
    assert np.isnan(optimizer.metrics()["recon_loss"])
    assert len(optimizer.archive) > 0


@pytest.mark.parametrize("representation", ["centred", "minmax"])
def test_normalised_representations_run_a_trial(representation: str) -> None:
    optimizer = make(seed=16, representation=representation)
    for _ in range(3):
        step(optimizer)
    assert optimizer.trainings == 2
    elites = optimizer.archive.elites
    assert elites is not None
    assert np.all((elites.desc >= 0.0) & (elites.desc <= 1.0))
    assert optimizer.settings()["aurora"]["representation"] == representation


def test_sim_and_the_other_algorithms_import_without_torch() -> None:
    code = (
        "import sys, sim, algorithms, algorithms.factory, algorithms.map_elites\n"
        "assert 'torch' not in sys.modules, 'torch was imported'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_the_input_width_follows_the_number_of_crank_angles() -> None:
    optimizer = AuroraMapElites(
        fitness="Fp", batch_size=200, mode="paper", seed=17, n_angles=12, **SMALL
    )
    genomes = optimizer.ask()
    optimizer.tell(genomes, evaluate(genomes, "Fp", "paper", n_angles=12))
    assert optimizer.encoder.n_inputs == 24
    assert optimizer.torch_state()["layers.0.weight"].shape == (64, 24)
    assert optimizer.metrics()["train_paths"] > 0
