"""The walk model under faults, on a real store: weights damaged four ways, or holding
values that are not numbers, are refused by name before any prediction is logged, and a
run's good predictions stay as they were."""

from __future__ import annotations

import io

import pytest
import torch
from mlflow.tracking import MlflowClient

from linkevo.algorithms.walk_model import WalkModel
from linkevo.sim.robot.walk_features import FEATURE_NAMES, FEATURES_VERSION
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.tracking import ensure_experiment
from linkevo.workers.trial_spec import TrialSpec
from tests.helpers.faults import refused
from tests.helpers.trials import record_trials


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """A store with a MAP-LIS trial that has good predicted walks (`walkpred.parquet`)."""
    root = tmp_path_factory.mktemp("faults-walk-model")
    uri, runs = record_trials(
        root, "0a1b2c3d4e5f", [TrialSpec("MAP-LIS", "Fp", evaluations=2000, batch_size=500)]
    )
    good = log_model(uri, root, WalkModel(len(FEATURE_NAMES)).state_dict())
    from linkevo.orchestrator.cli import main

    assert (
        main(["walkmodel", "predict", runs["MAP-LIS"], "--model", good, "--tracking-uri", uri]) == 0
    )
    return uri, runs["MAP-LIS"], root


def log_model(uri: str, root, weights: object | bytes) -> str:
    """A walk-model run whose `walk_model.pt` holds `weights` (a torch object, or bytes)."""
    client = MlflowClient(uri)
    run = client.create_run(
        ensure_experiment(uri),
        tags={layout.KIND: layout.WALK_MODEL, layout.FEATURES: FEATURES_VERSION},
    )
    path = root / layout.WALK_MODEL_PT
    if isinstance(weights, bytes):
        path.write_bytes(weights)
    else:
        buffer = io.BytesIO()
        torch.save(weights, buffer)
        path.write_bytes(buffer.getvalue())
    client.log_artifact(run.info.run_id, str(path))
    client.set_terminated(run.info.run_id)
    return run.info.run_id


def predictions(uri: str, run_id: str, tmp_path) -> bytes:
    return (
        tmp_path
        / MlflowClient(uri).download_artifacts(run_id, layout.WALK_PREDICTION, str(tmp_path))
    ).read_bytes()


def nan_weights() -> dict:
    state = WalkModel(len(FEATURE_NAMES)).state_dict()
    first = next(k for k in state if k.startswith("member0"))
    state[first] = torch.full_like(state[first], float("nan"))
    return state


@pytest.mark.parametrize(
    ("weights", "said"),
    [
        (b"\x8f\x03random bytes \x00\x17", "are damaged"),
        (b"", "are damaged"),
        (b"weights: [1, 2, 3]\n", "are damaged"),
        ([1, 2, 3], "a list, not tensors"),
        ("nan", "hold values that are not finite"),
    ],
)
def test_damaged_weights_are_refused_and_the_runs_predictions_kept(
    store, weights, said, tmp_path, capsys
):
    uri, run_id, root = store
    before = predictions(uri, run_id, tmp_path / "before")
    model = log_model(uri, root, nan_weights() if weights == "nan" else weights)
    line = refused(
        ["walkmodel", "predict", run_id, "--model", model, "--tracking-uri", uri], capsys
    )
    assert f"walk model {model}" in line and said in line
    assert predictions(uri, run_id, tmp_path / "after") == before
