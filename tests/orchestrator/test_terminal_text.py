"""Text from a store or a document reaches the terminal escaped: a tag or a linkage's meta
holding escape sequences can neither clear the screen nor retitle the window."""

from __future__ import annotations

import json

from mlflow.tracking import MlflowClient

from linkevo.orchestrator.cli import main
from linkevo.sim.linkage.genome import random_genomes
from linkevo.sim.linkage.linkage_doc import to_document
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.tracking import ensure_experiment

CLEAR_SCREEN = "\x1b[2J"
RETITLE = "\x1b]0;pwned\x07"


def test_a_grid_id_tag_with_escape_sequences_is_printed_escaped(tmp_path, capsys):
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    experiment = ensure_experiment(uri)
    tags = {layout.KIND: layout.GRID, layout.GRID_ID: f"evil{CLEAR_SCREEN}{RETITLE}"}
    MlflowClient(uri).create_run(experiment, tags=tags)
    assert main(["pull", "nosuchgrid", "--best", "--tracking-uri", uri]) == 2
    err = capsys.readouterr().err
    assert "no grid 'nosuchgrid'" in err
    assert "\x1b" not in err and "\x07" not in err
    assert "evil\\x1b[2J\\x1b]0;pwned\\x07" in err


def test_a_linkages_meta_with_escape_sequences_is_printed_escaped(tmp_path, capsys):
    import numpy as np

    genome = random_genomes(np.random.default_rng(4), 1)[0]
    doc = to_document(genome, meta={"approach": f"MAP-LIS{CLEAR_SCREEN}{RETITLE}"})
    path = tmp_path / "linkage.json"
    path.write_text(json.dumps(doc))
    code = main(
        [
            "hexapod",
            "simulate",
            "--linkage",
            str(path),
            "--floor",
            "flat",
            "--seconds",
            "0.5",
            "--repeats",
            "1",
            "--no-log",
        ]
    )
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "MAP-LIS\\x1b[2J" in out
    assert "\x1b" not in out + err and "\x07" not in out + err
