"""Store set-up: launches started together on a fresh sqlite store queue up, not race."""

from __future__ import annotations

import sqlite3
import subprocess
import sys
from pathlib import Path

from mlflow.tracking import MlflowClient

from linkevo.workers.store.tracking import (
    EXPERIMENT_DESCRIPTION,
    EXPERIMENT_KIND,
    ensure_experiment,
)

OPEN_STORE = """
import sys, time
from linkevo.workers.store.tracking import ensure_experiment
time.sleep(max(0.0, float(sys.argv[2]) - time.time()))  # all at once, none spinning
print(ensure_experiment(sys.argv[1], "linkevo"))
"""


def test_processes_opening_a_fresh_store_together_all_get_one_experiment(tmp_path: Path):
    """Without the lock MLflow's concurrent schema creation fails one or both writers
    (`duplicate column name`) and can leave `_alembic_tmp_*` tables behind. Three stores,
    three processes each, all nine opening at the same instant."""
    root = Path(__file__).resolve().parents[2]
    uris = [f"sqlite:///{tmp_path / f'store{attempt}' / 'mlflow.db'}" for attempt in range(3)]
    # Every process imports mlflow first, then opens its store at the same instant.
    start = __import__("time").time() + 12.0
    procs = {
        uri: [
            subprocess.Popen(
                [sys.executable, "-c", OPEN_STORE, uri, str(start)],
                cwd=root,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            for _ in range(3)
        ]
        for uri in uris
    }
    for uri, started in procs.items():
        outputs = [p.communicate(timeout=120) for p in started]
        for proc, (_, err) in zip(started, outputs, strict=True):
            assert proc.returncode == 0, err[-2000:]
        ids = {out.strip() for out, _ in outputs}
        assert len(ids) == 1
        database = uri.removeprefix("sqlite:///")
        tables = {
            row[0]
            for row in sqlite3.connect(database).execute(
                "select name from sqlite_master where type='table'"
            )
        }
        assert not any(t.startswith("_alembic_tmp") for t in tables)
        assert ensure_experiment(uri, "linkevo") == ids.pop()


def test_experiment_opens_as_model_development_with_a_description(tmp_path: Path):
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    experiment_id = ensure_experiment(uri, "linkevo")
    client = MlflowClient(uri)
    tags = client.get_experiment(experiment_id).tags
    assert tags.items() >= EXPERIMENT_KIND.items()
    assert tags["mlflow.note.content"] == EXPERIMENT_DESCRIPTION
    older = client.create_experiment("older")  # made without a description
    assert ensure_experiment(uri, "older") == older
    assert client.get_experiment(older).tags["mlflow.note.content"] == EXPERIMENT_DESCRIPTION
