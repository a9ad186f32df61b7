"""Walk maps under faults, on a real store and a real local Ray instance: a second walk map
of a run refused without touching the run's robot tag, a walk map that records the robot it
walked (its gait too), and a damaged warm start refused before any trial starts."""

from __future__ import annotations

import json

import pytest
from mlflow.tracking import MlflowClient

from linkevo.configs import shipped
from linkevo.orchestrator.cli import main
from linkevo.orchestrator.lease import Lease, Subject
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.runs import RunStore
from linkevo.workers.trial_spec import TrialSpec
from tests.helpers.faults import refused
from tests.helpers.trials import record_trials

GRID = "0c1c0c1c0c1c"


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    return record_trials(
        tmp_path_factory.mktemp("faults-walkmap"),
        GRID,
        [TrialSpec("MAP-LIS", "Fp", evaluations=4000, batch_size=1000, seed=2)],
    )


def slow_robot(tmp_path):
    """The shipped robot config with a gait half as fast (as a calibration might write)."""
    text = shipped("hexapod.toml").read_text(encoding="utf-8")
    path = tmp_path / "slow.toml"
    path.write_text(text.replace("speed_rpm = 25.0", "speed_rpm = 12.5", 1), encoding="utf-8")
    return path


def test_a_walk_map_records_the_robot_it_walked_gait_included(store, ray_local, tmp_path):
    uri, runs = store
    argv = ["walkmap", runs["MAP-LIS"], "--cells", "best:2", "--seconds", "1", "--floor", "flat"]
    assert main([*argv, "--config", str(slow_robot(tmp_path)), "--tracking-uri", uri]) == 0
    tags = MlflowClient(uri).get_run(runs["MAP-LIS"]).data.tags
    assert json.loads(tags[layout.WALK_MAP_ROBOT]) == {"gait": {"speed_rpm": 12.5}}


def test_a_refused_walk_map_leaves_the_runs_robot_tag(store, tmp_path, capsys):
    uri, runs = store
    run_id = runs["MAP-LIS"]
    client = MlflowClient(uri)
    before = client.get_run(run_id).data.tags.get(layout.WALK_MAP_ROBOT)
    subject = Subject.walk_map(run_id, "MAP-LIS/Fp/00")
    lease = Lease.take(RunStore(uri), subject)  # another walk map of the run is under way
    try:
        argv = ["walkmap", run_id, "--restart", "--seconds", "1", "--tracking-uri", uri]
        assert "by another" in refused(argv, capsys)
    finally:
        lease.release()
    assert client.get_run(run_id).data.tags.get(layout.WALK_MAP_ROBOT) == before


def test_a_damaged_warm_start_is_refused_before_any_trial(store, tmp_path, capsys):
    uri, runs = store
    client = MlflowClient(uri)
    run = client.create_run(
        client.get_run(runs["MAP-LIS"]).info.experiment_id,
        tags={layout.KIND: layout.TRIAL, layout.APPROACH: "MAP-LIS", layout.FITNESS: "Fp"},
    ).info.run_id
    folder = tmp_path / "art"
    folder.mkdir()
    repertoire = client.download_artifacts(runs["MAP-LIS"], layout.REPERTOIRE, str(folder))
    client.log_artifact(run, repertoire)
    (folder / layout.WALK_MAP).write_bytes(b"PAR1 not a table")
    client.log_artifact(run, str(folder / layout.WALK_MAP))
    grid = ["grid", str(shipped("walking.toml")), "--tracking-uri", uri]
    grid += ["--set", f'seed_from="{run}"', "--set", 'approaches=["MAP-LIS"]']
    grid += ["--set", "trials=1", "--set", "walks=2"]
    for argv in ([*grid, "--dry-run"], grid):
        said = refused(argv, capsys)
        assert f"walkmap.parquet of run {run} is not a readable parquet table" in said
    trials = client.search_runs(
        [e.experiment_id for e in client.search_experiments()],
        f"tags.`{layout.KIND}` = 'trial' and attributes.status != 'FINISHED'",
    )
    assert [t.info.run_id for t in trials] == [run]  # no trial started: only the damaged one
