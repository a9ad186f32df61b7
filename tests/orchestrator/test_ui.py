"""Tests `linkevo ui`: the MLflow UI on loopback, refusing a busy port, stopping its server
on SIGTERM, and landing a fresh browser on the trials with their metrics."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import pytest
from mlflow.tracking import MlflowClient

from linkevo.orchestrator.process_sessions import processes_using
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.tracking import RUNS_VIEW_KEY, ensure_experiment
from tests.helpers.browser import chromium

CLI = "import sys; from linkevo.orchestrator.cli import main; sys.exit(main())"
DOCS_IMG = Path(__file__).resolve().parents[2] / "docs" / "img"


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@contextlib.contextmanager
def _ui(uri: str, port: int) -> Iterator[tuple[subprocess.Popen, str]]:
    """Runs `linkevo ui` until its server answers; yields the process and the address it
    printed."""
    ui = subprocess.Popen(
        [sys.executable, "-c", CLI, "ui", "--tracking-uri", uri, "--port", str(port)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        ui.address_line = ui.stderr.readline()
        address = ui.address_line.split(" on ", 1)[1].split()[0]
        deadline = time.monotonic() + 120
        while True:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/health", timeout=2) as r:
                    assert r.status == 200
                    break
            except OSError:
                assert ui.poll() is None, "linkevo ui exited"
                assert time.monotonic() < deadline, "the UI did not answer /health"
                time.sleep(0.5)
        yield ui, address
    finally:
        ui.send_signal(signal.SIGTERM)
        try:
            ui.wait(timeout=60)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(ui.pid, signal.SIGKILL)
            ui.wait(timeout=30)


def test_a_killed_ui_takes_its_server_with_it(tmp_path):
    uri = f"sqlite:///{tmp_path / 'store' / 'mlflow.db'}"
    ensure_experiment(uri)
    with _ui(uri, _free_port()) as (ui, _address):
        assert processes_using(uri)
        ui.kill()  # SIGKILL: linkevo ui cannot clean up
        ui.wait(timeout=30)
        deadline = time.monotonic() + 90  # seconds when quiet; with a grid on every core,
        # reaping the server can take over 30 s
        while processes_using(uri) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not processes_using(uri)


def _grid_store(uri: str, n_trials: int) -> list[float]:
    """A grid's parent run and its nested trial runs, tagged and measured as the driver
    and the trial task write them; returns the trials' best losses."""
    experiment = ensure_experiment(uri)
    client = MlflowClient(tracking_uri=uri)
    grid_tags = {layout.KIND: layout.GRID, layout.GRID_ID: "a1b2c3d4e5f6"}
    parent = client.create_run(experiment, run_name="grid-a1b2c3d4e5f6", tags=grid_tags)
    losses = []
    for index in range(n_trials):
        key = layout.trial_key("MAP-LIS", "Fp", index)
        tags = grid_tags | {
            layout.KIND: layout.TRIAL,
            layout.PARENT: parent.info.run_id,
            layout.TRIAL_KEY: key,
            layout.APPROACH: "MAP-LIS",
            layout.FITNESS: "Fp",
            layout.TRIAL_INDEX: str(index),
        }
        run = client.create_run(experiment, run_name=key, tags=tags).info.run_id
        losses.append(17.25 + index)
        for name, value in {"best_loss": losses[-1], "coverage": 0.5, "qd_score": 9.0}.items():
            client.log_metric(run, name, value, step=1)
        client.set_terminated(run)
    client.set_terminated(parent.info.run_id)
    return losses


def test_ui_serves_every_trial_on_loopback_and_stops_with_its_server(tmp_path):
    """One UI on a grid of 120 trials: a fresh browser lands on every trial with its
    metrics; a second UI on the store, or one on a busy port, is refused; the server logs
    to its file; SIGTERM to `linkevo ui` stops its server."""
    from selenium.webdriver.common.by import By

    uri = f"sqlite:///{tmp_path / 'store' / 'mlflow.db'}"
    losses = _grid_store(uri, 120)  # more than the 100 runs a page of MLflow's UI holds
    port = _free_port()
    with _ui(uri, port) as (ui, address):
        request = f"http://127.0.0.1:{port}/ajax-api/2.0/mlflow/experiments/search?max_results=10"
        with urllib.request.urlopen(request, timeout=10) as r:
            names = [e["name"] for e in json.loads(r.read())["experiments"]]
        assert "linkevo" in names
        log = tmp_path / "store" / "mlflow-ui.log"
        assert log.is_file() and f"server log: {log}" in ui.address_line

        with chromium(tmp_path / "profile", size="2400,1000") as page:
            assert f"viewStateShareKey={RUNS_VIEW_KEY}" in address
            page.get(address)
            deadline = time.monotonic() + 90
            while True:
                body = page.find_element(By.TAG_NAME, "body").text
                if "best_loss" in body and f"{losses[0]:g}" in body:
                    break
                assert time.monotonic() < deadline, f"no best_loss column on the page: {body[:600]}"
                time.sleep(0.5)
            assert "workflowType=machine_learning" in page.current_url
            headers = page.find_elements(By.CSS_SELECTOR, "[role=columnheader]")
            header_text = " ".join(h.text for h in headers)
            for column in ("best_loss", "coverage", "qd_score", "approach", "fitness"):
                assert column in header_text, header_text
            for loss, index in zip(losses[:3], range(3), strict=True):  # trials, not folded
                assert f"MAP-LIS/Fp/{index:02d}" in body and f"{loss:g}" in body
            assert "Group: a1b2c3d4e5f6" in body  # trials grouped by grid, the group unfolded
            assert "120 matching runs" in body  # every trial loaded, no grid run among them
            assert "Load more" not in body
            assert "Model registry" in body  # the model-training sidebar, not GenAI's
            if os.environ.get("LINKEVO_DOCS_SCREENSHOTS"):
                page.save_screenshot(str(DOCS_IMG / "mlflow_trials.png"))

        second = subprocess.run(
            [sys.executable, "-c", CLI, "ui", "--tracking-uri", uri, "--port", str(_free_port())],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert second.returncode == 2, second.stderr
        assert "a UI already serves this store (pid " in second.stderr
        assert f"): open {address} , or stop it first" in second.stderr
        other = f"sqlite:///{tmp_path / 'other' / 'mlflow.db'}"
        ensure_experiment(other)
        busy = subprocess.run(
            [sys.executable, "-c", CLI, "ui", "--tracking-uri", other, "--port", str(port)],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert busy.returncode == 2 and f"--port {port}: not a free loopback port" in busy.stderr
        ui.send_signal(signal.SIGTERM)  # to linkevo ui alone: it stops its server
        assert ui.wait(timeout=60) == 0
        with pytest.raises(OSError):
            urllib.request.urlopen(f"http://127.0.0.1:{port}/health", timeout=2)
        deadline = time.monotonic() + 30
        while processes_using(uri) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not processes_using(uri)  # no server process on the store is left
