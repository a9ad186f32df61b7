"""Tests a real grid on a real local Ray instance with a real MLflow store."""

from __future__ import annotations

import csv
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mlflow.tracking import MlflowClient

from linkevo.orchestrator.commands.grid import summary
from linkevo.orchestrator.config import ConfigError
from linkevo.orchestrator.driver import launch
from linkevo.orchestrator.grid import CODE_VERSION_ENV, trial_dir, work_root
from linkevo.workers.store.tracking import ensure_experiment
from tests.helpers.grid import runs_by_key, tiny_grid

pytestmark = pytest.mark.ray

LINKEVO = "import sys; from linkevo.orchestrator.cli import main; sys.exit(main())"
"""Runs the `linkevo` CLI in a subprocess, whatever the console script's location."""
SPEC_PARAMS = {
    "approach",
    "fitness",
    "mode",
    "evaluations",
    "batch_size",
    "n_angles",
    "target",
}


def check_trial_runs(uri: str, grid, result, tmp_path: Path) -> None:
    """Asserts one FINISHED nested run per key with the documented params/metrics/artefacts."""
    client = MlflowClient(uri)
    by_key = runs_by_key(uri, grid.grid_id)
    assert sorted(by_key) == sorted(c.key for c in grid.cells)
    for cell in grid.cells:
        ((run_id, status),) = by_key[cell.key]
        assert status == "FINISHED"
        run = client.get_run(run_id)
        tags = run.data.tags
        assert tags["mlflow.parentRunId"] == result.parent_run_id
        assert tags["linkevo.kind"] == "trial"
        assert (tags["approach"], tags["fitness"]) == (cell.approach, cell.fitness)
        assert tags["seed"] == str(cell.seed)
        assert tags["trial_index"] == str(cell.index)
        assert run.info.run_name == cell.key
        assert set(run.data.params) >= SPEC_PARAMS
        assert "seed" not in run.data.params  # a tag, which MLflow's charts leave alone
        assert run.data.params["evaluations"] == str(grid.config.evaluations)
        history = client.get_metric_history(run_id, "evaluations")
        assert [m.step for m in history] == list(range(1, len(history) + 1))
        assert history[-1].value == grid.config.evaluations
        for name in ("best_loss", "mean_loss", "coverage", "qd_score"):
            assert len(client.get_metric_history(run_id, name)) == len(history)
        names = {a.path for a in client.list_artifacts(run_id)}
        kept = "repertoire" if cell.approach.startswith("MAP") else "population"
        expected = {"metrics.csv", f"{kept}.parquet", f"{kept}.png", "best_linkage.json"}
        assert expected | {"best_linkage.png", "settings.json"} <= names, names
        assert not any(name.startswith(".") for name in names)
        assert tags["stopped_by"] == "budget"
        local = client.download_artifacts(run_id, "metrics.csv", str(tmp_path))
        rows = list(csv.DictReader(Path(local).read_text().splitlines()))
        assert len(rows) == len(history)
        assert float(rows[-1]["best_loss"]) == pytest.approx(run.data.metrics["best_loss"])


def test_small_grid_ends_with_one_finished_run_per_trial_key(ray_local, tmp_path):
    grid = tiny_grid(tmp_path)
    result = launch(grid, progress=False)
    assert not result.failed
    uri = result.tracking_uri
    check_trial_runs(uri, grid, result, tmp_path)
    client = MlflowClient(uri)
    parent = client.get_run(result.parent_run_id)
    assert parent.info.status == "FINISHED"
    assert parent.info.run_name == f"grid-{grid.grid_id}"
    assert parent.data.tags["linkevo.kind"] == "grid"
    assert parent.data.tags["code_version"] == grid.code_version
    assert f"linkevo report {grid.grid_id}" in parent.data.tags["mlflow.note.content"]
    assert not parent.data.metrics  # the summary is one table, not loose metrics
    path = client.download_artifacts(parent.info.run_id, "grid_summary.json", str(tmp_path))
    table = json.loads(Path(path).read_text())
    rows = {(r[0], r[1]): dict(zip(table["columns"], r, strict=True)) for r in table["data"]}
    assert len(rows) == 4 and rows["EA", "Fp"]["finished"] == grid.config.trials
    best = min(o.best_loss for o in result.outcomes if o.trial_key.startswith("MAP-LIS/Fsl/"))
    assert rows["MAP-LIS", "Fsl"]["best_loss_min"] == best
    assert rows["MAP-LIS", "Fp"]["qd_score_median"] is not None
    assert (
        f"| MAP-LIS | Fsl | {grid.config.trials}/{grid.config.trials} | {best:.4g} |"
        in (parent.data.tags["mlflow.note.content"])
    )
    experiment = client.get_experiment(parent.info.experiment_id)
    assert experiment.tags["mlflow.experimentKind"] == "custom_model_development"
    assert parent.data.params["approaches"] == "['EA', 'MAP-LIS']"
    path = client.download_artifacts(parent.info.run_id, "grid_config.json", str(tmp_path))
    resolved = json.loads(Path(path).read_text())
    assert resolved == grid.config.to_dict()
    assert "grid_config.toml" in {a.path for a in client.list_artifacts(parent.info.run_id)}
    # One copy of a finished trial's files: MLflow's. The local folder is gone.
    out_dir = trial_dir(work_root(grid.config, uri), grid, grid.cells[0])
    assert not out_dir.exists()
    assert "EA" in summary(result, grid.config)

    with pytest.raises(ConfigError, match="pass --resume"):
        launch(grid, progress=False)
    again = launch(grid, resume=True, progress=False)
    assert sorted(again.skipped) == sorted(c.key for c in grid.cells)
    before = runs_by_key(uri, grid.grid_id)
    assert all(len(v) == 1 for v in before.values())

    # A larger `trials` on --resume extends the finished grid: only the new indices run.
    wider = tiny_grid(tmp_path, trials=3)
    assert wider.grid_id == grid.grid_id
    extended = launch(wider, resume=True, progress=False)
    assert sorted(extended.skipped) == sorted(before)
    after = runs_by_key(uri, grid.grid_id)
    assert sorted(set(after) - set(before)) == sorted(c.key for c in wider.cells if c.index == 2)
    assert all(after[key] == before[key] for key in before)  # the first trials untouched
    parent = client.get_run(result.parent_run_id)
    assert parent.data.tags["trials"] == "3"
    assert "| MAP-LIS | Fsl | 3/3 |" in parent.data.tags["mlflow.note.content"]
    path = client.download_artifacts(parent.info.run_id, "grid_config.json", str(tmp_path / "x"))
    assert json.loads(Path(path).read_text())["trials"] == 3
    with pytest.raises(ConfigError, match=r"'trials' = 2 is invalid .* allowed: >= 3"):
        launch(grid, resume=True, progress=False)


def test_a_copied_or_moved_store_keeps_working_and_never_writes_into_the_other(
    ray_local, tmp_path, capsys
):
    import shutil

    from linkevo.orchestrator.cli import main

    grid = tiny_grid(tmp_path, approaches=["MAP-LIS"], fitnesses=["Fp"], trials=1)
    first = launch(grid, progress=False)
    original = tmp_path / "store" / "mlartifacts"
    summaries = {p: p.read_bytes() for p in original.rglob("grid_summary.json")}
    assert len(summaries) == 1
    shutil.copytree(tmp_path / "store", tmp_path / "copy")
    copied = f"sqlite:///{tmp_path / 'copy' / 'mlflow.db'}"
    again = launch(
        tiny_grid(
            tmp_path, tracking_uri=copied, approaches=["MAP-LIS"], fitnesses=["Fp"], trials=1
        ),
        resume=True,
        progress=False,
    )
    assert again.parent_run_id == first.parent_run_id and not again.failed
    assert {p: p.read_bytes() for p in original.rglob("grid_summary.json")} == summaries
    assert list((tmp_path / "copy" / "mlartifacts").rglob("grid_summary.json"))

    (tmp_path / "copy").rename(tmp_path / "moved")
    moved = f"sqlite:///{tmp_path / 'moved' / 'mlflow.db'}"
    out = tmp_path / "pulled"
    assert (
        main(["pull", grid.grid_id, "--best", "--any", "--tracking-uri", moved, "--out", str(out)])
        == 0
    )
    assert (out / "linkage.json").is_file()
    page = tmp_path / "page.html"
    assert main(["explore", grid.grid_id, "--tracking-uri", moved, "--out", str(page)]) == 0
    assert page.stat().st_size > 1000
    assert not (tmp_path / "copy").exists()  # nothing written where the store was

    shutil.copy(tmp_path / "store" / "mlflow.db", tmp_path / "lonely.db")  # no artefacts
    lonely = f"sqlite:///{tmp_path / 'lonely.db'}"
    capsys.readouterr()
    assert main(["pull", grid.grid_id, "--best", "--any", "--tracking-uri", lonely]) == 2
    err = capsys.readouterr().err
    assert f"records its artefacts in {original}, not beside it" in err, err


def test_failed_trial_is_reported_and_the_others_finish(ray_local, tmp_path):
    grid = tiny_grid(tmp_path, approaches=["EA"], fitnesses=["Fp"], trials=2)
    uri = f"sqlite:///{tmp_path / 'store' / 'mlflow.db'}"
    broken = trial_dir(work_root(grid.config, uri), grid, grid.cells[1])
    broken.parent.mkdir(parents=True)
    broken.write_text("a file where the trial folder should be")
    result = launch(grid, progress=False)
    assert [o.trial_key for o in result.failed] == [grid.cells[1].key]
    by_key = runs_by_key(uri, grid.grid_id)
    assert [s for _, s in by_key[grid.cells[1].key]] == ["FAILED"]
    assert [s for _, s in by_key[grid.cells[0].key]] == ["FINISHED"]
    client = MlflowClient(uri)
    failed = client.get_run(by_key[grid.cells[1].key][0][0])
    assert "FileExistsError" in failed.data.tags["error"]
    assert client.get_run(result.parent_run_id).info.status == "FAILED"
    assert "failed trials:" in summary(result, grid.config)


def test_grid_logs_through_an_mlflow_server_over_http(ray_local, tmp_path, mlflow_server):
    grid = tiny_grid(
        tmp_path,
        tracking_uri=mlflow_server,
        work_dir=str(tmp_path / "work"),
        approaches=["MAP-LIS"],
        trials=1,
    )
    result = launch(grid, progress=False)
    assert not result.failed
    assert result.tracking_uri == mlflow_server
    check_trial_runs(mlflow_server, grid, result, tmp_path)
    left = [p.name for p in (tmp_path / "work" / "trials" / grid.grid_id).iterdir()]
    assert left == ["grid.json"]  # no trial folder: MLflow holds the one copy
    assert (tmp_path / "mlflow-server" / "artefacts").is_dir()  # the server holds them


def poll_finished(uri: str, grid_id: str, at_least: int, proc: subprocess.Popen) -> set[str]:
    """Returns the FINISHED keys once there are `at_least` of them (while `proc` runs)."""
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline:
        finished = {
            key
            for key, runs in runs_by_key(uri, grid_id).items()
            if any(status == "FINISHED" for _, status in runs)
        }
        if len(finished) >= at_least:
            return finished
        assert proc.poll() is None, "the driver ended before it was killed"
        time.sleep(0.2)
    raise AssertionError("no trial finished in time")


def test_killed_driver_resumes_only_the_missing_trials(ray_local, tmp_path, monkeypatch):
    # Pin the code version: a commit landing mid-test must not change the grid id.
    monkeypatch.setenv(CODE_VERSION_ENV, "kill-resume-test")
    grid = tiny_grid(tmp_path, approaches=["MAP-LIS"], evaluations=1000)
    uri = grid.config.tracking_uri
    address = ray_local.get_runtime_context().gcs_address
    command = [
        sys.executable,
        "-c",
        LINKEVO,
        "grid",
        str(tmp_path / "tiny.toml"),
        "--address",
        address,
        "--no-progress",
    ]
    ensure_experiment(uri)  # the poll below must not race the driver's schema creation
    driver = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    poll_finished(uri, grid.grid_id, 1, driver)
    driver.kill()
    driver.wait(timeout=30)
    before = runs_by_key(uri, grid.grid_id)
    finished_before = {k for k, runs in before.items() if runs[0][1] == "FINISHED"}
    missing = {c.key for c in grid.cells} - finished_before
    assert missing, "every trial finished before the kill"

    resumed = subprocess.run([*command, "--resume"], capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert f"({len(finished_before)} already finished before this launch)" in resumed.stdout
    after = runs_by_key(uri, grid.grid_id)
    client = MlflowClient(uri)
    for key in finished_before:
        assert after[key] == before[key]
    for key in missing:
        earlier = {run_id for run_id, _ in before.get(key, [])}
        new = [(run_id, status) for run_id, status in after[key] if run_id not in earlier]
        assert len(new) == 1
        assert new[0][1] == "FINISHED"
        assert all(status == "KILLED" for run_id, status in after[key] if run_id in earlier)
        steps = [m.step for m in client.get_metric_history(new[0][0], "evaluations")]
        assert steps == [1, 2, 3, 4, 5]


@pytest.mark.parametrize(("signum", "evaluators"), [(signal.SIGINT, 0), (signal.SIGTERM, 1)])
def test_a_signal_leaves_no_running_trial_and_says_how_to_resume(
    ray_local, tmp_path, monkeypatch, signum, evaluators
):
    # A plain trial task (K = 0) and one with an evaluator actor in its placement group.
    monkeypatch.setenv(CODE_VERSION_ENV, f"signal-test-{signum}")
    grid = tiny_grid(
        tmp_path,
        approaches=["MAP-LIS"],
        evaluations=2000,
        trials=3,
        evaluators_per_trial=evaluators,
    )
    uri = grid.config.tracking_uri
    address = ray_local.get_runtime_context().gcs_address
    command = [
        sys.executable,
        "-c",
        LINKEVO,
        "grid",
        str(tmp_path / "tiny.toml"),
        "--address",
        address,
        "--no-progress",
    ]
    ensure_experiment(uri)
    driver = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    poll_finished(uri, grid.grid_id, 1, driver)
    driver.send_signal(signum)
    _, err = driver.communicate(timeout=120)
    assert driver.returncode == 128 + signum, err[-3000:]
    name = signal.Signals(signum).name
    assert f"stopped by {name}:" in err and "marked KILLED" in err
    resume = f"-m linkevo.orchestrator grid {tmp_path / 'tiny.toml'} --address {address} --resume"
    assert resume in err  # the command as this driver was started
    assert "Traceback" not in err, err[-3000:]
    assert " INFO " not in err and "Token authentication" not in err  # a quiet terminal
    statuses = [status for runs in runs_by_key(uri, grid.grid_id).values() for _, status in runs]
    assert "RUNNING" not in statuses and "FINISHED" in statuses
    client = MlflowClient(uri)
    (parent,) = client.search_runs(
        [client.get_experiment_by_name("linkevo").experiment_id],
        f"tags.grid_id = '{grid.grid_id}' and tags.`linkevo.kind` = 'grid'",
    )
    assert parent.info.status == "KILLED"
