"""Tests for `linkevo pull`: a tracked linkage, its drawings and build sheet."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path
from xml.dom import minidom

import numpy as np
import pytest
from mlflow.tracking import MlflowClient

from linkevo import sim
from linkevo.orchestrator.cli import main
from linkevo.orchestrator.pull import build_sheet
from linkevo.sim.linkage.linkage_doc import FORMAT, to_document
from linkevo.sim.linkage.physical import physical_checks
from linkevo.sim.robot.leg import leg_from_genome
from linkevo.sim.robot.mounting import robot_spacers
from linkevo.sim.robot.parts import catalogue
from linkevo.workers.store.artifacts import write_json_atomic, write_parquet_atomic
from linkevo.workers.store.tracking import ensure_experiment

GRID = "0123456789ab"
"""A grid with two finished MAP-LIS/Fp trials, the second one better, and one EA/Fsl."""


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """A real sqlite store holding GRID."""
    root = tmp_path_factory.mktemp("store")
    uri = f"sqlite:///{root / 'mlflow.db'}"
    experiment = ensure_experiment(uri)
    client = MlflowClient(uri)
    client.create_run(experiment, tags={"grid_id": GRID, "linkevo.kind": "grid"})
    genomes = sim.random_genomes(np.random.default_rng(8), 300)
    ev = sim.evaluate(genomes)
    valid = np.flatnonzero(ev.error == 0)[:6]
    study = json.loads((Path(__file__).parents[1] / "data" / "study_cells.json").read_text())
    genomes[valid[0]] = study[0]["genome"]  # a study cell real parts build: the first best
    runs = []
    for rank, (approach, fitness, loss) in enumerate(
        (("MAP-LIS", "Fp", 40.0), ("MAP-LIS", "Fp", 25.0), ("EA", "Fsl", -30.0))
    ):
        tags = {"grid_id": GRID, "linkevo.kind": "trial", "approach": approach, "fitness": fitness}
        tags["trial_key"] = f"{approach}/{fitness}/{rank:02d}"
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
                "bin_0": np.array([0, 42]),
                "bin_1": np.array([17, 42]),
                "loss": ev.loss[valid[2:4]],
                "genome": genomes[valid[2:4]],
            },
        )
        client.log_artifacts(run.info.run_id, str(folder))
        client.set_terminated(run.info.run_id)
        runs.append(run.info.run_id)
    return uri, runs, genomes, valid


WANTED_TAGS = {
    "ITEMTYPE",
    "ITEMID",
    "COLOR",
    "MAXPRICE",
    "MINQTY",
    "QTYFILLED",
    "CONDITION",
    "REMARKS",
    "NOTIFY",
    "WANTEDSHOW",
    "WANTEDLISTID",
}


def bricklink_wanted_list(text: str) -> dict[str, int]:
    """Returns {item id: quantity} of a BrickLink wanted list, checked against BrickLink's
    published rules for its XML (bricklink.com help pages 198 and 2567, "Importing items on
    BrickLink with XML"): no XML declaration; one INVENTORY element holding one or more ITEM
    elements; each ITEM with its ITEMTYPE (S, P, M, B or G) and ITEMID, a colour ID (0
    unless a part or gear), a whole quantity above 0, and only the wanted list's elements."""
    assert not text.lstrip().startswith("<?xml")
    root = minidom.parseString(text).documentElement
    assert root.tagName == "INVENTORY"
    items = [n for n in root.childNodes if n.nodeType == n.ELEMENT_NODE]
    assert items and all(item.tagName == "ITEM" for item in items)
    out = {}
    for item in items:
        fields = {
            n.tagName: n.firstChild.data for n in item.childNodes if n.nodeType == n.ELEMENT_NODE
        }
        assert set(fields) <= WANTED_TAGS and {"ITEMTYPE", "ITEMID"} <= set(fields)
        assert fields["ITEMTYPE"] in {"S", "P", "M", "B", "G"} and fields["ITEMID"].strip()
        colour = int(fields.get("COLOR", "0"))
        assert colour >= 0 and (colour == 0 or fields["ITEMTYPE"] in {"P", "G"})
        assert fields["MINQTY"].isdigit() and int(fields["MINQTY"]) > 0
        assert fields["ITEMTYPE"] == "P" and colour in (11, 86)  # linkevo's: parts in two greys
        assert fields["ITEMID"] not in out  # one row per part (each in one colour)
        out[fields["ITEMID"]] = int(fields["MINQTY"])
    return out


def test_pull_writes_document_drawings_and_sheet(store, tmp_path, capsys):
    uri, runs, genomes, valid = store
    out = tmp_path / "best"
    assert main(["pull", runs[0], "--tracking-uri", uri, "--out", str(out), "--gif"]) == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(
        [
            "linkage.json",
            "linkage.png",
            "linkage.gif",
            "build_sheet.md",
            "build_sheet.csv",
            "path_overlay.png",
            "layers.png",
            "template.pdf",
            "leg.ldr",
            "robot.mpd",
            "parts.csv",
            "parts.xml",
        ]
    )
    rows = list(csv.DictReader((out / "build_sheet.csv").open()))
    doc = to_document(genomes[valid[0]])
    lego = json.loads((out / "linkage.json").read_text())["lego"]
    assert len(rows) == len(doc["beams"]) == len(lego["lengths"])
    for row, beam, whole in zip(rows, doc["beams"], lego["lengths"], strict=True):
        assert int(row["holes"]) == whole + 1  # the LEGO build's lengths, re-simulated
        assert abs(whole - beam["length"]) < 1 or whole == 1
        assert abs(float(row["error_mm"])) < 8.0
        beams = [catalogue().part(part.split()[0]) for part in row["part"].split(" + ")]
        assert sum(b.size for b in beams) >= whole + 1  # real beams long enough
    assert [int(r["layer"]) for r in rows] == lego["layers"]
    assert max(p["layer"] for p in lego["pieces"]) + 1 == lego["n_layers"]
    sheet = (out / "build_sheet.md").read_text()
    assert f"Layers: {lego['n_layers']}" in sheet and "- node 0: Technic Axle" in sheet
    # The parts a shop reads: the sheet's table, parts.csv and BrickLink's XML agree.
    table = re.findall(r"^\| (\w+) \| [^|]+ \| (\d+) \| (\d+) \|$", sheet, flags=re.M)
    listed = {part: int(robot) for part, _, robot in table}
    assert listed == {
        r["part"]: int(r["robot"]) for r in csv.DictReader((out / "parts.csv").open())
    }
    ordered = bricklink_wanted_list((out / "parts.xml").read_text())
    assert ordered == {catalogue().part(p).bricklink: n for p, n in listed.items()}
    assert "MAP-LIS / Fp" in (out / "build_sheet.md").read_text()
    assert f"pulling run {runs[0]} (MAP-LIS, Fp), its best linkage" in capsys.readouterr().err
    pulled = json.loads((out / "linkage.json").read_text())
    assert pulled["format"] == FORMAT and pulled["meta"]["run_id"] == runs[0]
    assert pulled["checks"] == to_document(genomes[valid[0]])["checks"]
    assert "Checks: " in (out / "build_sheet.md").read_text()
    leg = leg_from_genome(genomes[valid[0]])
    assert pulled["mounting"] == robot_spacers(leg)  # the study's robot, chosen as walked
    assert "Mounting: " in sheet


def test_pull_a_cell_by_its_bin_coordinates_and_list_the_cells(store, tmp_path, capsys):
    uri, runs, genomes, valid = store
    by_bins, by_cell = tmp_path / "bins", tmp_path / "cell"
    assert main(["pull", f"{runs[0]}:42,42", "--tracking-uri", uri, "--out", str(by_bins)]) == 0
    assert "cell 4242" in capsys.readouterr().err
    assert main(["pull", f"{runs[0]}:4242", "--tracking-uri", uri, "--out", str(by_cell)]) == 0
    assert (by_bins / "build_sheet.csv").read_text() == (by_cell / "build_sheet.csv").read_text()
    capsys.readouterr()
    assert main(["pull", runs[0], "--list", "--tracking-uri", uri]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == [
        "cell",
        "bins",
        "loss",
        "turns",
        "width",
        "height",
        "min_transmission_deg",
        "toggles",
        "max_stretch",
        "buildable",
    ]
    losses = [float(line.split()[2]) for line in lines[1:3]]
    assert losses == sorted(losses) and {line.split()[0] for line in lines[1:3]} == {"17", "4242"}
    checks = physical_checks(
        sim.decode(genomes[valid[2:4]]), sim.simulate(sim.decode(genomes[valid[2:4]]))
    )
    assert main(["pull", runs[0], "--list", "--buildable", "--tracking-uri", uri]) == 0
    listed = capsys.readouterr().out
    assert ("17 " in listed) == bool(checks.buildable[0])
    assert main(["pull", f"{runs[0]}:3,4,5", "--tracking-uri", uri, "--out", str(tmp_path)]) == 2
    assert "has 2 descriptors, so give 2 bin coordinates" in capsys.readouterr().err


def test_pull_a_cell_and_the_best_trial_of_a_grid(store, tmp_path):
    uri, runs, genomes, valid = store
    cell = tmp_path / "cell"
    assert main(["pull", f"{runs[0]}:4242", "--tracking-uri", uri, "--out", str(cell)]) == 0
    lego = json.loads((cell / "linkage.json").read_text())["lego"]
    sheet = build_sheet(to_document(genomes[valid[3]]), lego.get("lengths"))
    rows = list(csv.DictReader((cell / "build_sheet.csv").open()))
    assert [int(r["holes"]) for r in rows] == [r["holes"] for r in sheet]
    assert "LEGO build: " in (cell / "build_sheet.md").read_text()
    best = tmp_path / "grid-best"
    argv = ["pull", GRID, "--best", "--any", "--fitness", "Fp", "--tracking-uri", uri]
    assert main([*argv, "--out", str(best)]) == 0
    assert runs[1] in (best / "build_sheet.md").read_text()


def test_pull_best_passes_over_an_unbuildable_best_design(tmp_path, capsys):
    genomes = sim.random_genomes(np.random.default_rng(3), 2000)
    batch = sim.decode(genomes)
    checks = physical_checks(batch, sim.simulate(batch))
    valid = sim.evaluate(genomes).error == 0
    good = genomes[np.flatnonzero(checks.buildable & valid)[:2]]
    bad = genomes[np.flatnonzero(~checks.buildable & checks.turns_fully & valid)[:2]]
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    experiment = ensure_experiment(uri)
    client = MlflowClient(uri)
    client.create_run(experiment, tags={"grid_id": GRID, "linkevo.kind": "grid"})
    runs = []
    for index, (best, loss, cells) in enumerate(
        ((bad[0], 10.0, [(bad[1], 11.0), (good[0], 12.0)]), (good[1], 15.0, []))
    ):
        tags = {"grid_id": GRID, "linkevo.kind": "trial", "approach": "MAP-LIS", "fitness": "Fp"}
        run = client.create_run(experiment, tags={**tags, "trial_key": f"MAP-LIS/Fp/0{index}"})
        client.log_param(run.info.run_id, "mode", "paper")
        client.log_metric(run.info.run_id, "best_loss", loss)
        folder = tmp_path / f"art{index}"
        folder.mkdir()
        write_json_atomic(folder / "best_linkage.json", to_document(best))
        write_parquet_atomic(
            folder / "repertoire.parquet",
            {
                "cell": np.array([11 + c for c in range(len(cells))], dtype=np.int64),
                "bin_0": np.zeros(len(cells), dtype=np.int64),
                "bin_1": np.arange(len(cells), dtype=np.int64),
                "loss": np.array([c[1] for c in cells]),
                "genome": np.array([c[0] for c in cells]).reshape(len(cells), genomes.shape[1]),
            },
        )
        client.log_artifacts(run.info.run_id, str(folder))
        client.set_terminated(run.info.run_id)
        runs.append(run.info.run_id)
    out = tmp_path / "built"
    assert main(["pull", GRID, "--best", "--tracking-uri", uri, "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert f"best buildable design of grid {GRID}: MAP-LIS/Fp/00's cell 12" in err
    assert "passed over MAP-LIS/Fp/00's best linkage, loss 10: Checks: NOT buildable" in err
    pulled = json.loads((out / "linkage.json").read_text())
    assert pulled["checks"]["buildable"] and pulled["checks"] == to_document(good[0])["checks"]
    anyway = tmp_path / "any"
    assert main(["pull", GRID, "--best", "--any", "--tracking-uri", uri, "--out", str(anyway)]) == 0
    assert f"buildable or not: MAP-LIS/Fp/00's best linkage (run {runs[0]})" in (
        capsys.readouterr().err
    )
    assert not json.loads((anyway / "linkage.json").read_text())["checks"]["buildable"]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--buildable"], "--buildable works only with --list"),
        (["--any"], "--any works only with --best"),
        (["--approach", "EA"], "--approach works only with --best"),
        (["--list", "--gif"], "--gif works only with no --list"),
        (["--list", "--out", "x"], "--out works only with no --list"),
    ],
)
def test_pull_refuses_options_it_would_ignore(store, tmp_path, capsys, extra, message):
    uri, runs, _, _ = store
    assert main(["pull", runs[0], *extra, "--tracking-uri", uri]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_pull_best_asks_for_the_fitness_when_the_grid_has_two(store, tmp_path, capsys):
    uri = store[0]
    assert main(["pull", GRID, "--best", "--tracking-uri", uri, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "has trials of Fp and Fsl" in err and "--fitness Fp or --fitness Fsl" in err
    argv = ["pull", GRID, "--best", "--approach", "EA", "--fitness", "Fp", "--tracking-uri", uri]
    assert main([*argv, "--out", str(tmp_path)]) == 2
    assert "--approach 'EA'" not in capsys.readouterr().err  # EA exists; EA/Fp does not
    argv = ["pull", GRID, "--best", "--approach", "GA", "--fitness", "Fp", "--tracking-uri", uri]
    assert main([*argv, "--out", str(tmp_path)]) == 2
    assert "--approach 'GA': grid 0123456789ab has finished trials of EA, MAP-LIS" in (
        capsys.readouterr().err
    )


@pytest.mark.parametrize("ref", ["nope", "a'b", "fedcba987654"])
def test_pull_refuses_unknown_cell_and_grid(store, tmp_path, capsys, ref):
    uri, runs, _, _ = store
    assert main(["pull", f"{runs[0]}:5", "--tracking-uri", uri, "--out", str(tmp_path)]) == 2
    assert "cell 5 is not in the repertoire" in capsys.readouterr().err
    assert main(["pull", ref, "--best", "--tracking-uri", uri, "--out", str(tmp_path)]) == 2
    assert f"no grid {ref!r} in experiment 'linkevo'; known grids: {GRID}" in (
        capsys.readouterr().err
    )


def test_pull_never_creates_a_store(tmp_path, capsys):
    folder = tmp_path / "nothing"
    assert main(["pull", "x", "--tracking-uri", str(folder), "--out", str(tmp_path)]) == 2
    assert "no MLflow store at" in capsys.readouterr().err
    assert not folder.exists()
    assert main(["pull", "x", "--tracking-uri", "ftp://host/x", "--out", str(tmp_path)]) == 2
    assert "scheme 'ftp' is not supported" in capsys.readouterr().err


def test_pull_of_a_walking_trials_best_says_how_the_full_model_walked_it(store, tmp_path, capsys):
    uri, _, genomes, valid = store
    client = MlflowClient(uri)
    tags = {"grid_id": "fedcba987654", "linkevo.kind": "trial", "approach": "MAP-LIS"}
    run = client.create_run("1", tags={**tags, "fitness": "Fw", "trial_key": "MAP-LIS/Fw/00"})
    run_id = run.info.run_id
    client.log_param(run_id, "mode", "paper")
    client.log_metric(run_id, "best_loss", -60.0)
    genome = genomes[valid[0]]
    floor = {"full_breaks": False, "chaotic": False, "agrees": True, "slides": False}
    confirmed = {
        "genome": genome.tolist(),
        "agrees": False,
        "chaotic": False,
        "slides": True,
        "shape": {"size_cm": [20.0, 15.0], "stroke_cm": 9.0, "lift_cm": 3.0, "crank_share": 0.9},
        "repeats": 5,
        "floors": {
            "flat": {**floor, "full_mean_cm": 81.25, "slide_share": 0.7, "slides": True},
            "carpet": {**floor, "full_mean_cm": None, "full_breaks": True, "agrees": False},
        },
    }
    folder = tmp_path / "art"
    folder.mkdir()
    write_json_atomic(folder / "best_linkage.json", to_document(genome))
    write_json_atomic(folder / "best_confirmed.json", confirmed)
    client.log_artifacts(run_id, str(folder))
    client.set_terminated(run_id)
    out = tmp_path / "pulled"
    assert main(["pull", run_id, "--tracking-uri", uri, "--out", str(out)]) == 0
    said = (
        "flat 81.2 cm; carpet breaks per 10 s on the full model (5 hand-placed starts per "
        "floor); it DISAGREES with the lean model; SLIDES: most of its distance is its feet "
        "sliding"
    )
    assert f"confirmed walk: {said}" in capsys.readouterr().err
    assert f"Confirmed walk: {said}." in (out / "build_sheet.md").read_text()
    pulled = json.loads((out / "linkage.json").read_text())
    assert pulled["confirmed_walk"]["floors"]["flat"]["slide_share"] == 0.7
    assert "genome" not in pulled["confirmed_walk"]
