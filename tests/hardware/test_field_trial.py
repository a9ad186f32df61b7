"""Field trials round-trip through a real MLflow store (sqlite in tmp) into Table I."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from mlflow.tracking import MlflowClient

from linkevo.orchestrator.cli import main
from linkevo.workers.store.linkages import LinkageError, LinkageRef
from linkevo.workers.store.tracking import ensure_experiment

BEST_DOC = {"format": "test/1", "genome": [0.5] * 56, "note": "opaque to hardware/"}


@pytest.fixture(scope="module")
def store_uri(tmp_path_factory):
    """One sqlite store per module (creating the schema is the slow part)."""
    uri = f"sqlite:///{tmp_path_factory.mktemp('mlflow') / 'mlflow.db'}"
    ensure_experiment(uri)
    return uri


@pytest.fixture
def store(store_uri, request):
    """Returns (uri, client, experiment id) with an experiment of this test's own."""
    experiment_id = ensure_experiment(store_uri, f"hexapod-{request.node.name}")
    return store_uri, MlflowClient(tracking_uri=store_uri), experiment_id


def source_run(store, tmp_path, approach, genomes=None, grid="", best=BEST_DOC):
    """Creates a trial run like linkevo's: tags, mode param, best linkage, repertoire."""
    _, client, experiment_id = store
    tags = {"approach": approach, "fitness": "Fp"} | ({"grid_id": grid} if grid else {})
    run = client.create_run(experiment_id, tags=tags)
    run_id = run.info.run_id
    client.log_param(run_id, "mode", "paper")
    client.log_dict(run_id, {**best, "approach": approach}, "best_linkage.json")
    if genomes is not None:
        table = pa.table(
            {
                "cell": pa.array(list(genomes), pa.int64()),
                "genome": pa.array([list(g) for g in genomes.values()], pa.list_(pa.float64())),
                "loss": pa.array([0.1] * len(genomes), pa.float64()),
                "error": pa.array([0] * len(genomes), pa.int64()),
                "desc_0": pa.array([c // 100 / 100 for c in genomes], pa.float64()),
                "desc_1": pa.array([c % 100 / 100 for c in genomes], pa.float64()),
                "bin_0": pa.array([c // 100 for c in genomes], pa.int64()),
                "bin_1": pa.array([c % 100 for c in genomes], pa.int64()),
            }
        )
        path = tmp_path / "repertoire.parquet"
        pq.write_table(table, path)
        client.log_artifact(run_id, str(path))
    client.set_terminated(run_id)
    return run_id


def trial(uri, cfg, linkage, floor, distances, *extra):
    argv = [
        "hexapod",
        "trial",
        "--linkage",
        linkage,
        "--floor",
        floor,
        "--emulate",
        "--config",
        str(cfg),
        "--seconds",
        "0.2",
        "--repeats",
        str(len(distances)),
        "--tracking-uri",
        uri,
        *extra,
    ]
    if distances:
        argv += ["--distance-cm", *map(str, distances)]
    return main(argv)


def test_field_trials_round_trip_into_table_one(store, tmp_path, config_file, capsys):
    uri, client, experiment_id = store
    cfg = config_file("/dev/unused")
    wh = source_run(store, tmp_path, "MAP-WH")
    st = source_run(store, tmp_path, "MAP-ST")
    assert trial(uri, cfg, wh, "flat", [70.0, 77.2]) == 0
    assert trial(uri, cfg, wh, "carpet", [63.6]) == 0
    assert trial(uri, cfg, st, "flat", [39.4]) == 0
    assert trial(uri, cfg, st, "flat", [77.6], "--robot", "modified") == 0
    runs = client.search_runs([experiment_id], "tags.`linkevo.kind` = 'field_trial'")
    assert len(runs) == 4
    first = next(
        r for r in runs if r.data.tags["floor"] == "flat" and r.data.tags["approach"] == "MAP-WH"
    )
    tags = first.data.tags
    assert tags["source_run_id"] == wh and tags["source_cell"] == "best"
    assert (tags["approach"], tags["fitness"], tags["robot"]) == ("MAP-WH", "Fp", "first")
    assert first.data.metrics["mean_distance_cm"] == pytest.approx(73.6)
    history = client.get_metric_history(first.info.run_id, "distance_cm")
    assert [(m.step, m.value) for m in history] == [(0, 70.0), (1, 77.2)]
    local = client.download_artifacts(first.info.run_id, "linkage.json", str(tmp_path))
    assert json.loads(Path(local).read_text(encoding="utf-8")) == {**BEST_DOC, "approach": "MAP-WH"}
    files = [f.path for f in client.list_artifacts(first.info.run_id, "telemetry")]
    assert files == ["telemetry/repeat_1.csv", "telemetry/repeat_2.csv"]

    capsys.readouterr()
    experiment = client.get_experiment(experiment_id).name
    assert main(["hexapod", "table", "--tracking-uri", uri, "--experiment", experiment]) == 0
    assert capsys.readouterr().out.splitlines() == [
        f"no real field trials logged in experiment {experiment!r}",
        "4 emulator dry-run field-trial run(s) left out (--emulated shows them)",
    ]
    argv = ["hexapod", "table", "--tracking-uri", uri, "--experiment", experiment, "--emulated"]
    assert main(argv) == 0
    title, *lines = capsys.readouterr().out.splitlines()
    assert title == "Emulator dry-run field trials:"
    assert [c.strip() for c in lines[0].split("|")] == [
        "Approach",
        "First robot: flat",
        "First robot: carpet",
        "Modified robot: flat",
        "Modified robot: carpet",
    ]
    assert [c.strip() for c in lines[2].split("|")] == ["MAP-WH", "73.6 cm", "63.6 cm", "–", "–"]
    assert [c.strip() for c in lines[3].split("|")] == ["MAP-ST", "39.4 cm", "–", "77.6 cm", "–"]
    assert lines[4].startswith("– : no field trial")
    assert lines[5:] == [
        f"  MAP-WH: first robot run {wh}",
        f"  MAP-ST: first robot run {st}, modified robot run {st}",
    ]


def test_the_table_never_pools_trials_of_different_linkages(store, tmp_path, config_file, capsys):
    uri, client, experiment_id = store
    cfg = config_file("/dev/unused")
    legs = [
        source_run(store, tmp_path, "MAP-LIS", grid="a0", best={**BEST_DOC, "genome": [g] * 56})
        for g in (0.1, 0.2)
    ]
    other_grid = source_run(store, tmp_path, "MAP-LIS", grid="b1")
    for run_id, distance in zip([*legs, other_grid], (77.6, 168.7, 117.8), strict=True):
        assert trial(uri, cfg, run_id, "flat", [distance]) == 0
    capsys.readouterr()
    experiment = client.get_experiment(experiment_id).name
    argv = ["hexapod", "table", "--tracking-uri", uri, "--experiment", experiment, "--emulated"]
    assert main(argv) == 0
    _, _, _, *lines = capsys.readouterr().out.splitlines()
    rows = [[c.strip() for c in line.split("|")][:2] for line in lines[:3]]
    assert rows == [
        ["MAP-LIS (grid a0)", "77.6 cm"],
        ["MAP-LIS (grid a0)", "168.7 cm"],
        ["MAP-LIS (grid b1)", "117.8 cm"],
    ]
    assert f"  MAP-LIS (grid a0): first robot run {legs[1]}" in lines


def test_cell_reference_builds_the_document_from_the_repertoire_genome(
    store, tmp_path, config_file, monkeypatch
):
    from linkevo.sim.linkage.linkage_doc import from_document, to_document

    uri, client, experiment_id = store
    genome = np.random.default_rng(7).random(56)
    run_id = source_run(store, tmp_path, "MAP-LIS", {17: genome, 4242: np.full(56, 0.3)})
    monkeypatch.setattr("sys.stdin", io.StringIO("not a number\n40.4\n"))
    argv = [
        "hexapod",
        "trial",
        "--linkage",
        f"{run_id}:17",
        "--floor",
        "carpet",
        "--emulate",
        "--config",
        str(config_file("/dev/unused")),
        "--seconds",
        "0.2",
        "--repeats",
        "1",
        "--tracking-uri",
        uri,
        "--robot",
        "modified",
    ]
    assert main(argv) == 0
    (run,) = client.search_runs(
        [experiment_id], "tags.`linkevo.kind` = 'field_trial' and tags.source_cell = '17'"
    )
    assert run.data.metrics["mean_distance_cm"] == pytest.approx(40.4)
    local = client.download_artifacts(run.info.run_id, "linkage.json", str(tmp_path))
    document = json.loads(Path(local).read_text(encoding="utf-8"))
    rebuilt, mode = from_document(document)
    assert mode == "paper"
    assert np.allclose(rebuilt, genome)
    assert document == json.loads(json.dumps(to_document(genome, "paper")))


@pytest.mark.parametrize(
    ("argv_tail", "message"),
    [
        (
            ["--robot", "third"],
            "--robot: invalid choice: 'third' (choose from 'first', 'modified')",
        ),
        (["--repeats", "0"], "--repeats: '0' is not allowed: an integer in [1, 100]"),
        (["--repeats", "2", "--distance-cm", "5"], "--distance-cm has 1 value(s)"),
        (["--repeats", "1", "--distance-cm", "-5"], "--distance-cm [-5.0]: allowed finite"),
    ],
)
def test_bad_trial_arguments_are_usage_errors(argv_tail, message, tmp_path, config_file, capsys):
    uri = f"sqlite:///{tmp_path / 'never-created.db'}"
    argv = [
        "hexapod",
        "trial",
        "--linkage",
        "abc",
        "--floor",
        "flat",
        "--emulate",
        "--config",
        str(config_file("x")),
        "--tracking-uri",
        uri,
        *argv_tail,
    ]
    assert main(argv) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "never-created.db").exists()


def test_unknown_run_and_cell_are_named(store, tmp_path, config_file, capsys):
    uri = store[0]
    run_id = source_run(store, tmp_path, "MAP-AU", {3: np.full(56, 0.5)})
    cfg = str(config_file("x"))
    for linkage, message in [
        ("0123abc", "no MLflow run with id '0123abc'"),
        (f"{run_id}:99", f"{run_id}: cell 99 is not in the repertoire (1 filled"),
        (f"{run_id}:x", "expected RUN_ID, RUN_ID:CELL"),
        (f"{run_id}:1,2,3", "the repertoire has 2 descriptors, so give 2 bin coordinates"),
    ]:
        argv = [
            "hexapod",
            "trial",
            "--linkage",
            linkage,
            "--floor",
            "flat",
            "--emulate",
            "--config",
            cfg,
            "--tracking-uri",
            uri,
            "--repeats",
            "1",
            "--distance-cm",
            "1",
        ]
        assert main(argv) == 2
        assert message in capsys.readouterr().err


def test_linkage_ref_parsing():
    assert LinkageRef.parse("abc") == LinkageRef("abc", None)
    assert LinkageRef.parse("abc:12") == LinkageRef("abc", 12)
    assert LinkageRef.parse("abc:12,40") == LinkageRef("abc", bins=(12, 40))
    with pytest.raises(LinkageError, match="expected RUN_ID"):
        LinkageRef.parse(":3")
