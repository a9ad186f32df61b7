"""`linkevo hexapod simulate` and `linkevo hexapod study` on a real sqlite store and the
real engine: the JSON a user reads, the field trials logged, Table I predicted, bad input."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import numpy as np
import pytest
from mlflow.tracking import MlflowClient

from linkevo import sim
from linkevo.orchestrator.cli import main
from linkevo.sim.linkage.linkage_doc import to_document
from linkevo.sim.robot.hexapod import LEG_SLOTS, UNIT_M, Frame, Robot
from linkevo.sim.robot.leg import LegError, leg_from_genome
from linkevo.sim.robot.mounting import Mounting, robot_spacers
from linkevo.workers.store.artifacts import write_json_atomic, write_parquet_atomic
from linkevo.workers.store.tracking import ensure_experiment

GRID = "abcdef012345"
REPO = Path(__file__).resolve().parents[2]


def walkable(genomes: np.ndarray, count: int) -> list[int]:
    """The `count` lowest-F_p rows whose linkage turns a full turn (a leg can be built)."""
    found = []
    loss = sim.evaluate(genomes).loss
    for i in np.argsort(loss):
        try:
            leg_from_genome(genomes[i])
        except LegError:
            continue
        found.append(int(i))
        if len(found) == count:
            return found
    raise AssertionError("too few walkable genomes")


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """A real store with GRID: one finished MAP-LIS/Fp trial whose repertoire fills the
    5 × 5 regions (2, 2) (its best cell), (2, 3) and (3, 3), and (0, 0) far away."""
    root = tmp_path_factory.mktemp("walkstore")
    uri = f"sqlite:///{root / 'mlflow.db'}"
    experiment = ensure_experiment(uri)
    client = MlflowClient(uri)
    client.create_run(experiment, tags={"grid_id": GRID, "linkevo.kind": "grid"})
    genomes = sim.random_genomes(np.random.default_rng(5), 2000)
    rows = walkable(genomes, 4)
    ev = sim.evaluate(genomes[rows])
    tags = {"grid_id": GRID, "linkevo.kind": "trial", "approach": "MAP-LIS", "fitness": "Fp"}
    run = client.create_run(experiment, tags={**tags, "trial_key": "MAP-LIS/Fp/00"})
    run_id = run.info.run_id
    client.log_param(run_id, "mode", "paper")
    client.log_metric(run_id, "best_loss", 1.0)
    folder = root / "art"
    folder.mkdir()
    write_json_atomic(folder / "best_linkage.json", to_document(genomes[rows[0]]))
    bins = np.array([[50, 50], [50, 70], [70, 70], [5, 5]])
    write_parquet_atomic(
        folder / "repertoire.parquet",
        {
            "cell": bins[:, 0] * 100 + bins[:, 1],
            "bin_0": bins[:, 0],
            "bin_1": bins[:, 1],
            "loss": np.array([1.0, 2.0, 3.0, 4.0]),
            "genome": genomes[rows],
            "foot_x": ev.foot_x.astype(np.float32),
            "foot_y": ev.foot_y.astype(np.float32),
        },
    )
    client.log_artifacts(run_id, str(folder))
    client.set_terminated(run_id)
    return uri, run_id, genomes[rows]


def test_simulate_prints_the_table_one_json_and_logs_a_simulated_field_trial(store, capsys):
    uri, run_id, _ = store
    code = main(
        [
            "hexapod",
            "simulate",
            "--linkage",
            run_id,
            "--floor",
            "carpet",
            "--seconds",
            "2",
            "--repeats",
            "2",
            "--json",
            "--tracking-uri",
            uri,
        ]
    )
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    assert result["floor"] == "carpet" and result["seconds"] == 2.0
    assert len(result["distance_cm"]) == 2 and result["mean_distance_cm"] > 1
    assert result["mean_distance_cm"] == pytest.approx(np.mean(result["distance_cm"]), abs=0.01)
    for key in (
        "heading_drift_deg",
        "breaks",
        "reason",
        "torque_p95_of_stall",
        "pin_force_p99_n",
        "loop_error_max_mm",
        "body_height_cm",
        "foot_slip_mm_s",
    ):
        assert key in result
    assert result["model"] == "lean"
    assert 0 <= result["foot_deviation_max_mm"] < 1.0  # the lean model keeps the feet on path
    assert isinstance(result["caveats"], list)
    beyond = any(d is not None and d > result["bound_cm"] for d in result["distance_cm"])
    assert beyond == any("level-body bound" in c for c in result["caveats"])
    run = MlflowClient(uri).get_run(result["run_id"])
    assert run.data.params["simulated"] == "physics"
    assert run.data.params["model"] == "lean"
    assert run.data.tags["linkevo.kind"] == "field_trial"
    assert run.data.tags["source_run_id"] == run_id
    history = MlflowClient(uri).get_metric_history(result["run_id"], "distance_cm")
    assert [round(m.value, 2) for m in history] == result["distance_cm"]

    assert main(["hexapod", "table", "--tracking-uri", uri]) == 0
    table = capsys.readouterr().out
    assert "predicted by the 3-D simulation" in table
    assert f"– / {result['mean_distance_cm']:.1f} cm" in table


def test_simulate_walks_a_pulled_document_and_writes_its_pictures(store, tmp_path, capsys):
    _, _, genomes = store
    doc = tmp_path / "linkage.json"
    doc.write_text(json.dumps(to_document(genomes[1])))
    out = tmp_path / "pics"
    code = main(
        [
            "hexapod",
            "simulate",
            "--linkage",
            str(doc),
            "--floor",
            "flat",
            "--seconds",
            "1",
            "--repeats",
            "1",
            "--no-log",
            "--out",
            str(out),
            "--model",
            "full",
        ]
    )
    assert code == 0
    text = capsys.readouterr().out
    assert "flat floor" in text and "distance" in text and "full model" in text
    for name in ("walk.gif", "walk.png", "path.png", "contacts.png"):
        assert (out / name).stat().st_size > 1000


def test_a_leg_wider_than_the_spacing_is_mounted_apart_or_strikes_its_neighbours(tmp_path, capsys):
    genomes = sim.random_genomes(np.random.default_rng(5), 400)
    offsets = np.radians([Robot().phases_deg[s] for s in LEG_SLOTS])
    turn = np.linspace(0, 2 * np.pi, 120)[:, None] + offsets  # (120, 6) the gait's phases
    for genome in genomes:  # the first leg whose neighbours would meet, and spacers part
        try:
            leg = leg_from_genome(genome)
        except LegError:
            continue
        spacers = robot_spacers(leg)
        mounted = Mounting(dict.fromkeys(LEG_SLOTS, leg), spacers, Frame())
        if any(spacers.values()) and not mounted.strikes(turn):
            break
    assert np.ptp(leg.piece_ends()[..., 0]) * UNIT_M > Frame().leg_spacing  # sweeps wider
    doc = tmp_path / "wide.json"
    doc.write_text(json.dumps(to_document(genome)))
    walk = ["hexapod", "simulate", "--linkage", str(doc), "--floor", "flat", "--seconds", "2"]
    walk += ["--repeats", "1", "--no-log", "--json"]
    assert main(walk) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["spacers"] == spacers and "strike" not in result["reason"]
    built = tmp_path / "robot.toml"  # the same robot with every leg straight on its axle
    text = (REPO / "configs" / "hexapod.toml").read_text()
    built.write_text(text + "\n[mounting]\n" + "".join(f"{s} = 0\n" for s in LEG_SLOTS))
    assert main([*walk, "--config", str(built)]) == 0
    struck = json.loads(capsys.readouterr().out)
    assert struck["breaks"] and struck["spacers"] == dict.fromkeys(LEG_SLOTS, 0)
    assert re.search(r"the (\w+-\w+) and (\w+-\w+) legs strike each other", struck["reason"])


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--floor", "ice"], "--floor: invalid choice: 'ice' (choose from 'flat', 'carpet')"),
        (["--floor", "flat", "--seconds", "0"], "'0' is not allowed: a number of seconds in (0,"),
        (["--floor", "flat", "--seconds", "nan"], "--seconds: 'nan' is not allowed"),
        (["--floor", "flat", "--repeats", "0"], "'0' is not allowed: an integer in [1, 100]"),
        (["--floor", "flat", "--robot", "third"], "--robot: invalid choice: 'third'"),
        (["--floor", "flat", "--model", "cad"], "--model: invalid choice: 'cad'"),
    ],
)
def test_simulate_refuses_bad_input_before_any_work(store, args, message, capsys):
    uri, run_id, _ = store
    before = len(MlflowClient(uri).search_runs(["1"], max_results=1000))
    code = main(["hexapod", "simulate", "--linkage", run_id, "--tracking-uri", uri, *args])
    assert code != 0
    assert message in capsys.readouterr().err
    assert len(MlflowClient(uri).search_runs(["1"], max_results=1000)) == before


def test_simulate_refuses_a_file_that_is_not_a_linkage(tmp_path, capsys):
    bad = tmp_path / "notes.json"
    bad.write_text('{"hello": 1}')
    code = main(["hexapod", "simulate", "--linkage", str(bad), "--floor", "flat", "--no-log"])
    assert code != 0
    assert f"{bad}: not a linkage document" in capsys.readouterr().err


def test_study_predicts_first_and_modified_robots_from_the_5x5_map(store, tmp_path, capsys):
    uri, run_id, _ = store
    out = tmp_path / "study"
    code = main(
        [
            "hexapod",
            "study",
            GRID,
            "--trials-drawn",
            "1",
            "--seconds",
            "1",
            "--repeats",
            "1",
            "--out",
            str(out),
            "--tracking-uri",
            uri,
        ]
    )
    assert code == 0
    rows = list(csv.DictReader((out / "table1_predicted.csv").open()))
    assert [(r["approach"], r["draw"], r["robot"], r["floor"], r["model"]) for r in rows] == [
        ("MAP-LIS", "0", robot, floor, model)
        for robot in ("first", "modified")
        for floor in ("flat", "carpet")
        for model in ("lean", "full")
    ]
    first, modified = rows[0], rows[4]
    assert first["region"] == "2,2" and first["cell"] == "best"
    assert modified["region"] in ("2,3", "3,3")  # a neighbour of the first's region
    assert modified["rule"].startswith("sought: of the neighbours with shorter beams, the nearest")
    assert all(r["source_run_id"] == run_id for r in rows)
    assert all(r["field_trial_run_id"] for r in rows)
    for r in rows:  # the three-valued frailty verdict with the range it rests on
        verdict = r"(sound|frail|uncertain) \(give [\d.]+-[\d.]+ mm, axle [\d.]+-[\d.]+ N·mm\)"
        assert re.fullmatch(verdict, r["frailty"])
    printed = capsys.readouterr().out
    assert "candidate cell" not in printed  # the default rule walks no candidate
    verdicts = list(csv.DictReader((out / "table1_verdicts.csv").open()))
    lis_first = next(v for v in verdicts if v["claim"].startswith("The MAP-LIS first robot"))
    assert "incapable of walking" in lis_first["claim"]
    walked = [
        r["breaks"] != "True" and float(r["mean_distance_cm"] or "-inf") > 10.0 for r in rows[:4]
    ]
    for model, flat, carpet in (("lean", walked[0], walked[2]), ("full", walked[1], walked[3])):
        never = int(not (flat or carpet))
        assert f"walks on neither floor: {never} of 1 draws" in lis_first[f"evidence_{model}"]
        assert lis_first[f"verdict_{model}"] == ("direction only" if never else "not reproduced")
    assert "lean [" in printed and "full [" in printed


def test_study_with_the_walked_rule_walks_the_candidates(store, tmp_path, capsys):
    uri, _, _ = store
    code = main(
        [
            "hexapod",
            "study",
            GRID,
            "--modified",
            "walked",
            "--first",
            "best",
            "--seconds",
            "1",
            "--repeats",
            "1",
            "--tracking-uri",
            uri,
        ]
    )
    assert code == 0
    printed = capsys.readouterr().out
    assert printed.count("candidate cell") == 2  # the two filled neighbours, walked on flat
    assert "walked: the neighbour walking furthest on flat" in printed


def test_study_refuses_more_draws_than_trials_before_walking(store, tmp_path, capsys):
    uri, _, _ = store
    out = tmp_path / "none"
    code = main(
        ["hexapod", "study", GRID, "--trials-drawn", "2", "--out", str(out), "--tracking-uri", uri]
    )
    assert code == 2
    err = capsys.readouterr()
    assert "--trials-drawn 2 is invalid for MAP-LIS: allowed 1..1" in err.err
    assert "on flat" not in err.out and not out.exists()


def test_sign_verdicts_follow_the_rule():
    from linkevo.orchestrator.table_one_verdicts import sign_verdict

    assert sign_verdict(9, 10) == "reproduced"  # two-sided exact p 0.021
    assert sign_verdict(8, 10) == "direction only"  # p 0.11
    assert sign_verdict(5, 10) == "not reproduced"
    assert sign_verdict(1, 10) == "contradicted"
    assert sign_verdict(1, 1) == "direction only"  # one draw can show no more


def test_the_sought_rule_takes_the_nearest_path_with_the_builders_change():
    from linkevo.orchestrator.walk_study import path_distance, path_traits

    angles = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    ellipse = (3 * np.cos(angles), np.sin(angles))
    traits = path_traits(*ellipse, [{"length": 2.0}, {"length": 4.0}])
    assert traits["width"] == pytest.approx(6.0, abs=0.05)
    assert traits["height"] == pytest.approx(2.0, abs=0.05)
    assert traits["mean_beam"] == 3.0
    flat_bottom = (ellipse[0], np.maximum(ellipse[1], -0.5))
    assert path_traits(*flat_bottom, [])["flatness"] > traits["flatness"]
    moved = (ellipse[0] + 10, ellipse[1] - 4)
    assert path_distance(ellipse, moved) == pytest.approx(0.0, abs=1e-12)
    assert path_distance(ellipse, flat_bottom) > 0
