"""Tests a grid on `linkevo cluster up`: PostgreSQL behind an MLflow server with proxied
artefacts, and a Ray head plus two worker nodes started with `ray start`, one of which is
stopped mid-grid."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
from mlflow.tracking import MlflowClient

from linkevo.orchestrator import config
from linkevo.orchestrator.grid import Grid
from linkevo.orchestrator.local_cluster import (
    ClusterError,
    ClusterSettings,
    ClusterState,
    down,
    stop_node,
    up,
)
from tests.helpers.grid import running_on, runs_by_key, tiny_config_file

pytestmark = pytest.mark.ray


@pytest.fixture(scope="module")
def cluster(tmp_path_factory) -> ClusterState:
    """Three 1-CPU worker nodes: each test that stops one leaves two for the next."""
    folder = tmp_path_factory.mktemp("cluster")
    state = up(ClusterSettings(dir=folder, workers=3, cpus_per_worker=1))
    yield state
    down(folder)  # nothing to do when a test stopped it already


def linkevo(*args: str, env: dict[str, str], cwd: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "linkevo.orchestrator", *args],
        env={**os.environ, **env},
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def test_a_walking_trial_walks_on_two_nodes_and_resumes_after_losing_one(
    cluster: ClusterState, tmp_path: Path
) -> None:
    cfg = tiny_config_file(
        tmp_path,
        approaches=["MAP-LIS"],
        fitnesses=["Fw"],
        trials=1,
        walks=160,
        walk_batch=16,
        evaluators_per_trial=2,
        checkpoint_every=1,
        work_dir=str(tmp_path / "work"),
    )
    grid_id = Grid.from_config(config.load(cfg)).grid_id
    uri = cluster.tracking_uri
    grid = linkevo(
        "grid",
        str(cfg),
        "--address",
        cluster.address,
        "--tracking-uri",
        uri,
        "--no-progress",
        env=cluster.env,
        cwd=tmp_path,
    )
    client = MlflowClient(uri)
    deadline = time.monotonic() + 240
    victim = None
    while victim is None:
        assert time.monotonic() < deadline, "the walking trial did not get going"
        assert grid.poll() is None, f"the grid ended first:\n{grid.stdout.read()}"
        for node in cluster.workers:
            key = running_on(uri, grid_id, node.node_id)
            runs = runs_by_key(uri, grid_id).get(key or "", [])
            walked = [client.get_run(r).data.metrics.get("walks", 0) for r, _ in runs]
            if key and max(walked, default=0) >= 32:
                victim = node
        time.sleep(0.2)
    stop_node(cluster, victim, force=True)  # the node of the trial task and of one actor
    output, _ = grid.communicate(timeout=420)
    assert grid.returncode == 0, output

    runs = runs_by_key(uri, grid_id)["MAP-LIS/Fw/00"]
    assert sorted(status for _, status in runs) == ["FINISHED", "KILLED"]
    finished = next(r for r, status in runs if status == "FINISHED")
    log = pd.read_parquet(client.download_artifacts(finished, "walks.parquet", str(tmp_path)))
    walked_on = set(log.loc[log["stage"] == "walked", "node"])
    workers = {victim.node_id} | {n.node_id for n in cluster.workers}
    assert walked_on <= workers and len(walked_on) >= 2, walked_on  # both actors' nodes
    assert victim.node_id in walked_on  # the checkpoint kept the lost node's walks
    assert client.get_run(finished).data.metrics["walks"] >= 160


def test_a_grid_survives_a_stopped_worker_node_and_reads_back_through_the_server(
    cluster: ClusterState, tmp_path: Path
) -> None:
    assert MlflowClient(cluster.tracking_uri).search_experiments() is not None
    cfg = tiny_config_file(
        tmp_path,
        approaches=["EA", "MAP-LIS"],
        fitnesses=["Fp"],
        trials=2,
        evaluations=60_000,
        batch_size=500,
        evaluators_per_trial=0,
        work_dir=str(tmp_path / "work"),
    )
    grid_id = Grid.from_config(config.load(cfg)).grid_id
    uri = cluster.tracking_uri
    grid = linkevo(
        "grid",
        str(cfg),
        "--address",
        cluster.address,
        "--tracking-uri",
        uri,
        "--no-progress",
        env=cluster.env,
        cwd=tmp_path,
    )
    victim = cluster.workers[0]
    deadline = time.monotonic() + 240
    key = None
    while key is None:
        assert time.monotonic() < deadline, "no trial ran on the first worker node"
        assert grid.poll() is None, f"the grid ended first:\n{grid.stdout.read()}"
        key = running_on(uri, grid_id, victim.node_id)
        time.sleep(0.2)
    stop_node(cluster, victim, force=True)  # that node's processes, by their session id
    output, _ = grid.communicate(timeout=300)
    assert grid.returncode == 0, output

    by_key = runs_by_key(uri, grid_id)
    assert len(by_key) == 4
    for runs in by_key.values():
        assert [status for _, status in runs].count("FINISHED") == 1
    assert sorted(status for _, status in by_key[key]) == ["FINISHED", "KILLED"]

    client = MlflowClient(uri)
    for runs in by_key.values():
        run_id = next(r for r, status in runs if status == "FINISHED")
        assert client.get_run(run_id).info.artifact_uri.startswith("mlflow-artifacts:")
        got = client.download_artifacts(run_id, "best_linkage.json", str(tmp_path))
        assert len(json.loads(Path(got).read_text())["genome"]) == 56
    mine = {run_id for runs in by_key.values() for run_id, _ in runs}
    stored = [
        p for p in Path(cluster.dir, "artifacts").rglob("best_linkage.json") if mine & set(p.parts)
    ]
    assert len(stored) == 4  # proxied: the server wrote them, into its artefact folder

    report = linkevo(
        "report",
        grid_id,
        "--tracking-uri",
        uri,
        "--out",
        str(tmp_path / "report"),
        env=cluster.env,
        cwd=tmp_path,
    )
    out, _ = report.communicate(timeout=300)
    assert report.returncode == 0, out
    assert (tmp_path / "report" / "report.html").stat().st_size > 10_000
    pull = linkevo(
        "pull",
        grid_id,
        "--best",
        "--tracking-uri",
        uri,
        "--out",
        str(tmp_path / "pulled"),
        env=cluster.env,
        cwd=tmp_path,
    )
    out, _ = pull.communicate(timeout=120)
    assert pull.returncode == 0, out
    assert len(json.loads((tmp_path / "pulled" / "linkage.json").read_text())["genome"]) == 56


def test_down_leaves_no_process_or_port_behind(cluster: ClusterState) -> None:
    from linkevo.orchestrator.process_sessions import processes_using, session_members

    sessions = [n.sid for n in cluster.nodes] + [cluster.mlflow_sid]
    assert all(session_members(sid) for sid in sessions)
    stopped = down(Path(cluster.dir))
    assert stopped[-2:] == ["mlflow server", "postgresql"]
    assert not [pid for sid in sessions for pid in session_members(sid)]
    assert not processes_using(cluster.pg_data, cluster.ray_temp)
    for port in (cluster.postgres_port, cluster.mlflow_port, cluster.ray_port):
        with socket.socket() as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            probe.bind(("127.0.0.1", port))  # raises if anything still listens
    assert not Path(cluster.pg_data).exists() and ClusterState.load(Path(cluster.dir)) is None
    assert down(Path(cluster.dir)) == []


def test_bad_settings_are_refused_before_anything_starts(tmp_path: Path) -> None:
    with pytest.raises(ClusterError, match="workers must be an integer >= 1, got 0"):
        ClusterSettings(dir=tmp_path, workers=0)
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(ClusterError, match=f"mlflow_port {port} is already in use"):
            up(ClusterSettings(dir=tmp_path / "c", mlflow_port=port))
    assert not (tmp_path / "c").exists()
