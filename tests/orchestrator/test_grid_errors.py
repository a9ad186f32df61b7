"""Tests that bad grid input fails with a clear message before any trial starts."""

from __future__ import annotations

import socket

import pytest
import ray

from linkevo.orchestrator.cli import main
from tests.helpers.grid import tiny_config_file


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
        (None, "evaluators_per_trial=64", "reserves 64 CPU"),
        (None, "trial_cpus=64", "reserves 65 CPU"),
        (None, "evaluators_per_trial=0;trial_cpus=0", "'trial_cpus' = 0.0 is invalid"),
        (None, "options.MAP-AU.initial_epoch=3", "unknown option(s) 'initial_epoch' for MAP-AU"),
        (None, "trial_cpus=nan", "'trial_cpus' = nan is invalid"),
        (None, "max_seconds=inf", "'max_seconds' = inf is invalid: allowed: a finite number"),
        (None, "batch_size=1000000000;evaluations=1000000000", "a batch needs about"),
        (None, "n_angles=100000000", "'n_angles' = 100000000 is invalid: allowed: at most 3,600"),
        (None, "evaluations=1000000000000000", "allowed: at most batch_size x 1,000,000"),
        ("trials = 2 # caf\xe9\n", None, "not UTF-8 text (byte 16 is 0xe9)"),
        (None, "trials=1000000000", "'trials' = 1000000000 is invalid: allowed: at most 1,000"),
        (None, "max_retries=1000000", "'max_retries' = 1000000 is invalid: allowed: at most 100"),
        (None, f'experiment="{"x" * 600}"', "allowed: a name of 1 to 200 printable characters"),
        (None, 'experiment="a\\u001b[2J"', "allowed: a name of 1 to 200 printable characters"),
    ],
)
@pytest.mark.parametrize("dry_run", [False, True])
def test_bad_grid_input_fails_before_anything_starts(
    tmp_path, capsys, toml_text, override, expected, dry_run
):
    """Refused before Ray starts or the store is written, by a launch and by --dry-run."""
    store = tmp_path / "store"
    path = tiny_config_file(tmp_path, tracking_uri=f"sqlite:///{store / 'm.db'}")
    if toml_text is not None:
        path.write_bytes(toml_text.encode("latin-1"))
    args = ["grid", str(path), "--no-progress", *(["--dry-run"] if dry_run else [])]
    for one in [] if override is None else override.split(";"):
        args += ["--set", one.format(port=closed_port())]
    if override is not None and "MAP-AU" in override:
        args += ["--set", 'approaches=["MAP-AU"]']
    code = main(args)
    err = capsys.readouterr().err
    assert (code, expected in err) == (2, True), err
    assert not ray.is_initialized()
    assert not store.exists()


def _truncated_sqlite(path) -> bytes:
    import sqlite3

    with sqlite3.connect(path) as db:
        db.execute("create table t (x text)")
        db.executemany("insert into t values (?)", [("x" * 1000,)] * 100)
    return path.read_bytes()[: path.stat().st_size // 2]


@pytest.mark.parametrize(
    ("damage", "expected"),
    [
        (lambda path: b"", "is empty (0 bytes)"),
        (_truncated_sqlite, "is damaged"),
        (lambda path: b"this is not a database, it is a note", "is not an MLflow (SQLite) store"),
    ],
)
def test_dry_run_checks_the_store_as_a_launch_does(tmp_path, capsys, damage, expected):
    store = tmp_path / "store" / "m.db"
    store.parent.mkdir()
    content = damage(store)
    store.write_bytes(content)
    path = tiny_config_file(tmp_path, tracking_uri=f"sqlite:///{store}")
    assert main(["grid", str(path), "--dry-run"]) == 2
    assert expected in capsys.readouterr().err
    assert store.read_bytes() == content


def test_ui_refuses_a_missing_store(tmp_path, capsys):
    code = main(["ui", "--tracking-uri", f"sqlite:///{tmp_path / 'none.db'}"])
    assert code == 2
    assert "no MLflow store" in capsys.readouterr().err
