"""Tests the run layout's trial keys, id checks, quoting and paged search on a real store."""

from __future__ import annotations

import sqlite3

import pytest
from mlflow.tracking import MlflowClient

from linkevo.workers.store import run_layout as layout
from linkevo.workers.store import runs as runs_module
from linkevo.workers.store.runs import RunStore
from linkevo.workers.store.tracking import ensure_experiment


def test_a_trial_key_parses_back_into_its_cell():
    key = layout.trial_key("MAP-LIS", "Fp", 3)
    assert key == "MAP-LIS/Fp/03"
    assert layout.parse_trial_key(key) == ("MAP-LIS", "Fp", 3)
    assert layout.parse_trial_key("NSGA2/Fsl/117") == ("NSGA2", "Fsl", 117)
    for bad in ("MAP-LIS/Fp", "MAP-LIS/Fp/3", "../Fp/03", "MAP LIS/Fp/03"):
        with pytest.raises(ValueError, match="allowed APPROACH/FITNESS/NN"):
            layout.parse_trial_key(bad)


@pytest.mark.parametrize("bad", ["../../EVIL", "..", ".hidden", "a/b", "a'b", "", "x" * 65])
def test_an_id_that_could_name_another_folder_or_change_a_search_is_refused(bad):
    with pytest.raises(ValueError, match="is not an id"):
        layout.checked_id(bad, "the grid_id tag")
    assert layout.checked_id("8298b853678f", "the grid_id tag") == "8298b853678f"


def test_a_value_with_a_quote_never_reaches_a_filter():
    assert layout.where(layout.TRIAL, "FINISHED", grid_id="g1") == (
        "tags.`linkevo.kind` = 'trial' and tags.`grid_id` = 'g1' and attributes.status = 'FINISHED'"
    )
    with pytest.raises(ValueError, match="cannot be searched for"):
        layout.where(layout.GRID, grid_id="x' or tags.grid_id != '")


def test_search_pages_through_every_run(tmp_path, monkeypatch):
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    experiment = ensure_experiment(uri)
    client = MlflowClient(uri)
    for index in range(7):
        tags = {layout.KIND: layout.TRIAL, layout.GRID_ID: "g1"}
        client.create_run(experiment, tags={**tags, layout.TRIAL_KEY: f"EA/Fp/{index:02d}"})
    client.create_run(experiment, tags={layout.KIND: layout.TRIAL, layout.GRID_ID: "g2"})
    monkeypatch.setattr(runs_module, "PAGE", 3)  # three pages for the seven runs
    store = RunStore(uri)
    runs = store.trial_runs("g1")
    assert sorted(r.data.tags[layout.TRIAL_KEY] for r in runs) == [
        f"EA/Fp/{i:02d}" for i in range(7)
    ]
    assert len(store.search(layout.where(layout.TRIAL), limit=4)) == 4
    one = store.trial_runs("g1", trial_key="EA/Fp/05")
    assert [r.data.tags[layout.TRIAL_KEY] for r in one] == ["EA/Fp/05"]


def test_an_error_tag_holds_the_message_not_the_sql():
    import sqlalchemy.exc

    orig = sqlite3.OperationalError("database or disk is full")
    exc = sqlalchemy.exc.OperationalError("INSERT INTO metrics VALUES (?, ?)", ("a", 1), orig)
    text = layout.error_text(exc)
    assert text == "OperationalError: (sqlite3.OperationalError) database or disk is full"
    long = layout.error_text(OSError(28, "No space left on device", "/runs/trials/x" * 100))
    assert long.startswith("OSError: [Errno 28] No space left on device: '/runs/trials/x")
    assert len(long) == layout.ERROR_CHARS
