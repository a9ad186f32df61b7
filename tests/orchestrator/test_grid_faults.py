"""The grid under faults, on real Ray and a real MLflow store: two drivers on one grid, a
driver killed outright (what it listened on, what it left running) and resumed."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mlflow.tracking import MlflowClient

from linkevo.orchestrator import config
from linkevo.orchestrator.cli import main
from linkevo.orchestrator.grid import Grid
from linkevo.orchestrator.lease import LEASE_TTL_S, Holder
from linkevo.orchestrator.reaper import stat_of, tree
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.tracking import ensure_experiment, store_lock
from tests.helpers.grid import runs_by_key, tiny_config_file
from tests.helpers.mlflow_server import free_port, start_server
from tests.helpers.sockets import is_loopback, listening_addresses

CLI = "import sys; from linkevo.orchestrator.cli import main; sys.exit(main())"


def _grid(tmp_path: Path) -> tuple[Path, str, str]:
    """A tiny grid long enough to be caught running: its config file, store and id."""
    uri = f"sqlite:///{tmp_path / 'store' / 'mlflow.db'}"
    path = tiny_config_file(tmp_path, tracking_uri=uri, evaluations=3000, max_concurrent_trials=2)
    return path, uri, Grid.from_config(config.load(path)).grid_id


class _Linkevo:
    """A `linkevo` process whose output goes to a file (a pipe nobody reads while it runs
    could fill up and block it)."""

    def __init__(self, log: Path, *args: str, **popen) -> None:
        self.log = log
        with open(log, "w") as out:
            self.process = subprocess.Popen(
                [sys.executable, "-c", CLI, *args], stdout=out, stderr=subprocess.STDOUT, **popen
            )
        self.pid = self.process.pid

    def running(self) -> bool:
        assert self.process.poll() is None, f"linkevo ended early:\n{self.output()[-4000:]}"
        return True

    def finish(self, timeout: float) -> tuple[int, str]:
        """Waits for the process; returns its exit code and output."""
        try:
            code = self.process.wait(timeout=timeout)
        finally:
            if self.process.poll() is None:
                self.process.kill()
        return code, self.output()

    def output(self) -> str:
        return self.log.read_text(errors="replace")


def _lease(uri: str, grid_id: str) -> Holder | None:
    # Under the store's lock, as the driver opens it: a fresh sqlite store is created by
    # whichever opens it first, and MLflow's schema migration does not survive two at once.
    with store_lock(uri):
        experiment = MlflowClient(uri).get_experiment_by_name("linkevo")
    text = None if experiment is None else experiment.tags.get(layout.lease_tag(grid_id))
    return None if text is None else Holder(**json.loads(text))


def _wait_for(predicate, seconds: float, what: str) -> None:
    deadline = time.monotonic() + seconds
    while not predicate():
        assert time.monotonic() < deadline, what
        time.sleep(0.2)


def _one_finished(uri: str, grid_id: str) -> bool:
    try:
        with store_lock(uri):  # as `_lease`: never the second to create a fresh store
            runs = runs_by_key(uri, grid_id)
        return any(s == "FINISHED" for r in runs.values() for _, s in r)
    except Exception:
        return False


def test_a_lease_binds_while_renewed_by_a_live_process():
    now = time.time()
    me = Holder(os.uname().nodename, os.getpid(), now, now, "a")
    assert me.alive(now)
    assert not me.alive(now + LEASE_TTL_S + 1)  # not renewed: expired
    gone = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        capture_output=True,
        text=True,
        check=True,
    )
    dead = Holder(os.uname().nodename, int(gone.stdout), now, now, "b")
    assert not dead.alive(now)  # this host, its process gone: free at once
    elsewhere = Holder("another-host", int(gone.stdout), now, now, "c")
    assert elsewhere.alive(now)  # another host: bound until it expires


def test_the_same_grid_launched_twice_runs_once(tmp_path):
    path, uri, grid_id = _grid(tmp_path)
    first = _Linkevo(tmp_path / "first.log", "grid", str(path), "--no-progress")
    try:
        _wait_for(lambda: first.running() and _lease(uri, grid_id) is not None, 120, "no lease")
        for extra in ([], ["--resume"]):
            second = _Linkevo(tmp_path / "second.log", "grid", str(path), "--no-progress", *extra)
            code, err = second.finish(timeout=120)
            assert code == 2, err
            assert f"grid {grid_id} is being run by another driver pid {first.pid}" in err
            assert "Traceback" not in err, err[-4000:]
    finally:
        code, err = first.finish(timeout=600)
    assert code == 0, err
    runs = runs_by_key(uri, grid_id)
    assert len(runs) == 8
    assert all(statuses == [(statuses[0][0], "FINISHED")] for statuses in runs.values()), runs
    assert _lease(uri, grid_id) is None  # handed back at the end


def _alive(pids: set[int]) -> list[int]:
    """The processes among `pids` still running (zombies run nothing and are left out)."""
    return sorted(pid for pid in pids if stat_of(pid) is not None)


def test_a_killed_driver_listened_on_loopback_left_nothing_and_is_resumed(tmp_path):
    path, uri, grid_id = _grid(tmp_path)
    first = _Linkevo(
        tmp_path / "first.log", "grid", str(path), "--no-progress", start_new_session=True
    )
    try:
        _wait_for(lambda: first.running() and _one_finished(uri, grid_id), 300, "none finished")
        processes = set(tree(first.pid))  # the driver's Ray instance, trials and reaper
        listening = listening_addresses(processes)
        assert len(listening) >= 3, listening  # the GCS, the raylet, workers at least
        assert all(is_loopback(a) for each in listening.values() for a in each), listening
        os.kill(first.pid, signal.SIGKILL)  # the driver alone: no clean-up, lease left behind
        first.finish(timeout=30)
        deadline = time.monotonic() + 15
        while (left := _alive(processes)) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not left, f"outlived the driver by 15 s: {left}"
        assert _lease(uri, grid_id).pid == first.pid
        again = _Linkevo(tmp_path / "again.log", "grid", str(path), "--no-progress", "--resume")
        code, err = again.finish(timeout=600)
        assert code == 0, err
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(first.pid, signal.SIGKILL)
    runs = runs_by_key(uri, grid_id)
    finished = [k for k, r in runs.items() if any(s == "FINISHED" for _, s in r)]
    assert len(finished) == 8
    assert all(sum(s == "FINISHED" for _, s in r) == 1 for r in runs.values())
    assert _lease(uri, grid_id) is None


@pytest.fixture(scope="module")
def finished_grid(tmp_path_factory) -> tuple[Path, Path, str]:
    """A finished tiny grid: its config, its store folder (store and trial folders), id."""
    tmp = tmp_path_factory.mktemp("finished")
    uri = f"sqlite:///{tmp / 'store' / 'mlflow.db'}"
    path = tiny_config_file(tmp, tracking_uri=uri)  # a quick one: only its store is damaged
    grid_id = Grid.from_config(config.load(path)).grid_id
    code, err = _Linkevo(tmp / "grid.log", "grid", str(path), "--no-progress").finish(600)
    assert code == 0, err
    return path, tmp / "store", grid_id


def _damaged_copy(finished_grid, tmp_path: Path, damage) -> tuple[list[str], Path]:
    """Copies the finished grid's store folder, damages the store file; returns the
    `--set` arguments that point the grid's config at the copy, and the copy's store."""
    _path, store, _grid_id = finished_grid
    copy = tmp_path / "store"
    shutil.copytree(store, copy)
    damage(copy / "mlflow.db")
    return ["--set", f'tracking_uri="sqlite:///{copy / "mlflow.db"}"'], copy / "mlflow.db"


def _refused(args: list[str], capsys) -> str:
    """Runs linkevo in this process (an exception would fail the test: no traceback);
    returns its error output, after checking it was refused as bad input (exit 2)."""
    code = main(args)
    err = capsys.readouterr().err
    assert code == 2, err
    return err


@pytest.mark.parametrize(
    ("damage", "expected"),
    [
        (lambda db: db.write_bytes(b""), "is empty (0 bytes)"),
        (lambda db: os.truncate(db, db.stat().st_size // 2), "is damaged"),
        (lambda db: db.write_bytes(b"not a database" * 10), "is not an MLflow (SQLite) store"),
    ],
)
def test_a_damaged_store_is_refused_with_its_path_and_nothing_runs(
    finished_grid, tmp_path, capsys, damage, expected
):
    path, _store, grid_id = finished_grid
    uri_args, db = _damaged_copy(finished_grid, tmp_path, damage)
    before = db.read_bytes()
    for args in (
        ["grid", str(path), "--resume", "--no-progress", *uri_args],
        ["report", grid_id, "--tracking-uri", str(db.parent), "--out", str(tmp_path / "r")],
        ["ui", "--tracking-uri", f"sqlite:///{db}", "--port", "1"],
    ):
        err = _refused(args, capsys)
        assert expected in err and str(db) in err, err
    assert db.read_bytes() == before  # not re-initialised, not written
    assert not (tmp_path / "r").exists()


def test_resume_on_a_replaced_store_is_refused_saying_where_the_grid_ran(
    finished_grid, tmp_path, capsys
):
    path, _store, grid_id = finished_grid
    uri_args, db = _damaged_copy(finished_grid, tmp_path, lambda db: db.unlink())
    ensure_experiment(f"sqlite:///{db}")  # a new, valid store in its place
    err = _refused(["grid", str(path), "--resume", "--no-progress", *uri_args], capsys)
    assert f"holds no run of grid {grid_id}" in err
    assert str(db.parent / "trials" / grid_id / "grid.json") in err
    assert not runs_by_key(f"sqlite:///{db}", grid_id)  # nothing ran again


def _server_grid(tmp_path: Path, outage_s: float) -> tuple[Path, str, str, int]:
    """A tiny grid tracked by a real `mlflow server`: config, server URI, grid id, port."""
    port = free_port()
    uri = f"http://127.0.0.1:{port}"
    path = tiny_config_file(
        tmp_path,
        tracking_uri=uri,
        work_dir=str(tmp_path / "work"),
        evaluations=3000,
        max_concurrent_trials=2,
        server_outage_s=outage_s,
    )
    return path, uri, Grid.from_config(config.load(path)).grid_id, port


def test_a_tracking_server_that_comes_back_or_goes_for_good(tmp_path):
    """Killed mid-grid and restarted, the server lets the grid go on; killed for good, the
    driver stops within its limit with the resume command, and the resume completes."""
    limit = 30.0
    path, uri, grid_id, port = _server_grid(tmp_path, outage_s=limit)
    folder = tmp_path / "server"
    server = start_server(folder, port)
    driver = _Linkevo(tmp_path / "driver.log", "grid", str(path), "--no-progress")
    try:
        _wait_for(lambda: driver.running() and _one_finished(uri, grid_id), 300, "none finished")
        server.terminate()
        server.wait(timeout=30)
        time.sleep(6)  # with the restart, silent for a few health checks, within the limit
        server = start_server(folder, port)
        _wait_for(lambda: "answers again" in driver.output(), 60, "the return went unnoticed")
        server.terminate()  # now for good
        server.wait(timeout=30)
        gone = time.monotonic()
        code, err = driver.finish(timeout=300)
        took = time.monotonic() - gone
    finally:
        server.kill()
        driver.finish(timeout=60)
    assert f"the tracking server {uri} has not answered since" in err
    assert code == 1 and "Traceback" not in err, err[-4000:]
    assert took < limit + 40, took  # the limit, a health check, stopping the trials
    assert f"stopped: the tracking server {uri} has not answered since" in err
    assert "complete the grid with:" in err and "--resume" in err
    server = start_server(folder, port)
    try:
        again = _Linkevo(tmp_path / "again.log", "grid", str(path), "--no-progress", "--resume")
        code, err = again.finish(timeout=600)
        assert code == 0, err[-4000:]
        runs = runs_by_key(uri, grid_id)
    finally:
        server.terminate()
        server.wait(timeout=30)
    assert len(runs) == 8
    assert all(sum(s == "FINISHED" for _, s in r) == 1 for r in runs.values()), runs
