"""Tests for `linkevo pull`: a tracked linkage, its drawings and build sheet."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from mlflow.tracking import MlflowClient

import sim
from orchestrator.cli import main
from orchestrator.pull import build_sheet
from sim.linkage_doc import to_document
from workers.artifacts import write_json_atomic, write_parquet_atomic
from workers.tracking import ensure_experiment


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """A real sqlite store with two finished trials of one grid, the second one better."""
    root = tmp_path_factory.mktemp("store")
    uri = f"sqlite:///{root / 'mlflow.db'}"
    experiment = ensure_experiment(uri)
    client = MlflowClient(uri)
    genomes = sim.random_genomes(np.random.default_rng(8), 300)
    ev = sim.evaluate(genomes)
    valid = np.flatnonzero(ev.error == 0)[:6]
    runs = []
    for rank, loss in enumerate((40.0, 25.0)):
        tags = {"grid_id": "g1", "linkevo.kind": "trial", "approach": "MAP-LIS", "fitness": "Fp"}
        run = client.create_run(experiment, tags=tags)
        client.log_param(run.info.run_id, "mode", "paper")
        client.log_metric(run.info.run_id, "best_loss", loss)
        folder = root / f"art{rank}"
        folder.mkdir()
        write_json_atomic(folder / "best_linkage.json", to_document(genomes[valid[rank]]))
        write_parquet_atomic(
            folder / "repertoire.parquet",
            {
                "cell": np.array([17, 4242]),
                "loss": ev.loss[valid[2:4]],
                "genome": genomes[valid[2:4]],
            },
        )
        client.log_artifacts(run.info.run_id, str(folder))
        client.set_terminated(run.info.run_id)
        runs.append(run.info.run_id)
    return uri, runs, genomes, valid


def test_pull_writes_document_drawings_and_sheet(store, tmp_path, capsys):
    uri, runs, genomes, valid = store
    out = tmp_path / "best"
    assert main(["pull", runs[0], "--tracking-uri", uri, "--out", str(out), "--gif"]) == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(
        ["linkage.json", "linkage.png", "linkage.gif", "build_sheet.md", "build_sheet.csv"]
    )
    rows = list(csv.DictReader((out / "build_sheet.csv").open()))
    doc = to_document(genomes[valid[0]])
    assert len(rows) == len(doc["beams"])
    for row, beam in zip(rows, doc["beams"], strict=True):
        assert int(row["holes"]) == max(round(beam["length"]), 1) + 1
        assert abs(float(row["error_mm"])) <= 4.0 + 1e-9 or round(beam["length"]) == 0
    assert "MAP-LIS / Fp" in (out / "build_sheet.md").read_text()


def test_pull_a_cell_and_the_best_trial_of_a_grid(store, tmp_path):
    uri, runs, genomes, valid = store
    cell = tmp_path / "cell"
    assert main(["pull", f"{runs[0]}:4242", "--tracking-uri", uri, "--out", str(cell)]) == 0
    sheet = build_sheet(to_document(genomes[valid[3]]))
    rows = list(csv.DictReader((cell / "build_sheet.csv").open()))
    assert [int(r["holes"]) for r in rows] == [r["holes"] for r in sheet]
    best = tmp_path / "grid-best"
    assert main(["pull", "g1", "--best", "--tracking-uri", uri, "--out", str(best)]) == 0
    assert runs[1] in (best / "build_sheet.md").read_text()


def test_pull_refuses_unknown_cell_and_grid(store, tmp_path, capsys):
    uri, runs, _, _ = store
    assert main(["pull", f"{runs[0]}:5", "--tracking-uri", uri, "--out", str(tmp_path)]) == 2
    assert "cell 5 is not in the repertoire" in capsys.readouterr().err
    assert main(["pull", "nope", "--best", "--tracking-uri", uri, "--out", str(tmp_path)]) == 2
    assert "no FINISHED trial" in capsys.readouterr().err
