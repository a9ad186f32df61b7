"""`linkevo hexapod study` under faults, on a real store and the real engine: a grid with
no MAP-Elites F_p trial, an output it cannot write, and SIGTERM, which stops it as Ctrl-C
does (a message, no run left RUNNING)."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest
from mlflow.tracking import MlflowClient

from linkevo.workers.trial_spec import TrialSpec
from tests.helpers.faults import refused
from tests.helpers.trials import record_trials

CLI = "import sys; from linkevo.orchestrator.cli import main; sys.exit(main())"


@pytest.fixture(scope="module")
def grids(tmp_path_factory):
    """Two grids in two stores: one of an EA trial only, one of a MAP-LIS F_p trial."""
    root = tmp_path_factory.mktemp("faults-study")
    ea = record_trials(root / "ea", "0e0a0e0a0e0a", [TrialSpec("EA", "Fp", 1000, 500)])
    lis = record_trials(root / "lis", "0f1f0f1f0f1f", [TrialSpec("MAP-LIS", "Fp", 4000, 1000)])
    return ea[0], lis[0]


def test_a_grid_without_map_elites_fp_trials_is_refused(grids, tmp_path, capsys):
    said = refused(["hexapod", "study", "0e0a0e0a0e0a", "--tracking-uri", grids[0]], capsys)
    assert "has no finished MAP-Elites trial with Fp" in said


def test_an_out_that_is_a_file_is_refused_before_any_walk(grids, tmp_path, capsys):
    blocker = tmp_path / "tables"
    blocker.write_text("")
    argv = ["hexapod", "study", "0f1f0f1f0f1f", "--tracking-uri", grids[1], "--out", str(blocker)]
    assert f"--out {str(blocker)!r} is a file" in refused(argv, capsys)


def test_sigterm_stops_the_study_as_ctrl_c_does(grids, tmp_path):
    uri = grids[1]
    argv = (
        f"hexapod study 0f1f0f1f0f1f --trials-drawn 1 --repeats 1 --seconds 5 --tracking-uri {uri}"
    )
    log = tmp_path / "study.log"
    with open(log, "w") as out:
        command = [sys.executable, "-u", "-c", CLI, *argv.split()]  # -u: lines as printed
        study = subprocess.Popen(command, stdout=out, stderr=out)
    deadline = time.monotonic() + 120
    while "first robot" not in log.read_text() and time.monotonic() < deadline:
        assert study.poll() is None, log.read_text()
        time.sleep(0.2)
    study.terminate()
    assert study.wait(timeout=60) == 143
    assert "linkevo hexapod: interrupted (SIGTERM)" in log.read_text()
    client = MlflowClient(uri)
    ids = [e.experiment_id for e in client.search_experiments()]
    running = "attributes.status = 'RUNNING' and tags.`linkevo.kind` = 'field_trial'"
    assert client.search_runs(ids, running) == []
