"""Tests that MlflowRecorder gathers metrics, sends them in time and loses none."""

from __future__ import annotations

import numpy as np
from mlflow.tracking import MlflowClient

from linkevo.workers.store.mlflow_recorder import MAX_BATCH, MlflowRecorder
from linkevo.workers.store.tracking import ensure_experiment

NAMES = [f"metric_{k}" for k in range(12)]


def new_run(tmp_path) -> tuple[MlflowClient, str]:
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    client = MlflowClient(uri)
    run_id = client.create_run(ensure_experiment(uri, "recorder")).info.run_id
    return client, run_id


def steps(client: MlflowClient, run_id: str, name: str) -> list[int]:
    return sorted(m.step for m in client.get_metric_history(run_id, name))


def test_first_iteration_goes_out_at_once_then_metrics_wait_for_the_interval(tmp_path):
    client, run_id = new_run(tmp_path)
    recorder = MlflowRecorder(client, run_id, send_every_s=3600)
    recorder.log_iteration(1, dict.fromkeys(NAMES, 1.0))
    assert steps(client, run_id, "metric_0") == [1]
    for iteration in range(2, 6):
        recorder.log_iteration(iteration, dict.fromkeys(NAMES, float(iteration)))
    assert steps(client, run_id, "metric_0") == [1]  # gathered, not sent yet
    recorder.flush()
    assert steps(client, run_id, "metric_11") == [1, 2, 3, 4, 5]
    assert client.get_run(run_id).data.metrics["metric_5"] == 5.0


def test_more_metrics_than_one_batch_allows_are_all_written(tmp_path):
    client, run_id = new_run(tmp_path)
    recorder = MlflowRecorder(client, run_id, send_every_s=3600)
    iterations = MAX_BATCH // len(NAMES) + 40  # about 1,500 metrics gathered at once
    values = np.linspace(0.0, 1.0, iterations)
    for iteration, value in enumerate(values, start=1):
        recorder.log_iteration(iteration, dict.fromkeys(NAMES, float(value)))
    recorder.flush()
    history = client.get_metric_history(run_id, "metric_7")
    assert sorted(m.step for m in history) == list(range(1, iterations + 1))
    assert sorted(m.value for m in history) == sorted(values.tolist())


def test_every_iteration_is_sent_when_the_interval_is_zero(tmp_path):
    client, run_id = new_run(tmp_path)
    recorder = MlflowRecorder(client, run_id, send_every_s=0)
    for iteration in range(1, 4):
        recorder.log_iteration(iteration, {"loss": float(iteration)})
        assert steps(client, run_id, "loss") == list(range(1, iteration + 1))


def test_a_metric_that_does_not_apply_in_an_iteration_is_not_logged(tmp_path):
    client, run_id = new_run(tmp_path)
    recorder = MlflowRecorder(client, run_id, send_every_s=0)
    recorder.log_iteration(1, {"best_loss": 3.0, "recon_loss": float("nan")})
    recorder.log_iteration(2, {"best_loss": 2.0, "recon_loss": 0.25})
    assert steps(client, run_id, "recon_loss") == [2]
    assert steps(client, run_id, "best_loss") == [1, 2]


def test_result_files_are_logged_and_hidden_temporary_files_are_not(tmp_path):
    client, run_id = new_run(tmp_path)
    out = tmp_path / "trial"
    (out / "checkpoint").mkdir(parents=True)
    for name in ("metrics.csv", "repertoire.parquet", "repertoire.png", "notes.txt"):
        (out / name).write_text("x")
    (out / ".repertoire.tmp-host-99999-abcd.parquet").write_text("a killed writer's")
    (out / "checkpoint" / "state.npz").write_text("local only")
    MlflowRecorder(client, run_id).log_artifacts(out)
    logged = sorted(a.path for a in client.list_artifacts(run_id))
    assert logged == ["metrics.csv", "repertoire.parquet", "repertoire.png"]
