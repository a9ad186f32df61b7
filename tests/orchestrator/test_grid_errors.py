"""Tests that bad grid input fails with a clear message before any trial starts."""

from __future__ import annotations

import socket

import pytest
import ray
from grid_helpers import tiny_config_file

from orchestrator.cli import main


def closed_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@pytest.mark.parametrize(
    ("toml_text", "override", "expected"),
    [
        (None, 'approaches=["EA","MAP-XY"]', "'MAP-XY' is invalid: allowed values: EA, NSGA2"),
        (None, "evaluations=-1", "'evaluations' = -1 is invalid: allowed: an integer >= 1"),
        ("trials = [1,\n", None, "malformed TOML"),
        (None, "options.EA.bogus=1", "unknown option(s) 'bogus' for EA"),
        (None, "evaluations=100", "evaluations must be an integer >= the batch size (200)"),
        (None, 'tracking_uri="http://127.0.0.1:{port}"', "is unreachable"),
        pytest.param(None, "evaluators_per_trial=64", "reserves 64 CPU", marks=pytest.mark.ray),
    ],
)
def test_bad_grid_input_fails_before_any_trial(tmp_path, capsys, toml_text, override, expected):
    path = tiny_config_file(tmp_path, tracking_uri=f"sqlite:///{tmp_path / 'store' / 'm.db'}")
    if toml_text is not None:
        path.write_text(toml_text)
    args = ["grid", str(path), "--no-progress"]
    if override is not None:
        args += ["--set", override.format(port=closed_port())]
    code = main(args)
    err = capsys.readouterr().err
    assert code == 2
    assert expected in err, err
    assert not ray.is_initialized()
    trial_runs = list((tmp_path / "store").glob("trials/*/*"))
    assert trial_runs == []


def test_ui_refuses_a_missing_store(tmp_path, capsys):
    code = main(["ui", "--tracking-uri", f"sqlite:///{tmp_path / 'none.db'}"])
    assert code == 2
    assert "no MLflow store" in capsys.readouterr().err
