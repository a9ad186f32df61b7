"""`linkevo hexapod calibrate` on a real sqlite store and the real engine: field trials
made by the simulator with a hidden gait speed, logged as a real robot's, give the hidden
speed back; the written config is the one every command then takes; simulated runs and bad
names are refused before any walk."""

from __future__ import annotations

import json
import tomllib

import numpy as np
import pytest

from linkevo import sim
from linkevo.hardware.config import load_config
from linkevo.hardware.field_trial import log_field_trial
from linkevo.orchestrator.calibration import FieldTrial, simulated_cm, with_values
from linkevo.orchestrator.cli import main
from linkevo.sim.linkage.linkage_doc import to_document
from linkevo.sim.robot.leg import LegError, leg_from_genome
from linkevo.workers.store.linkages import SourceLinkage
from linkevo.workers.store.run_layout import PHYSICS, REAL
from linkevo.workers.store.tracking import ensure_experiment

HIDDEN_SPEED_RPM = 19.0
"""The robot's gait speed the field trials are made with (the shipped config says 25)."""
SECONDS = 2.0
TOLERANCE = 0.03
"""The calibrated speed is within 3 % of the hidden one (the search's own tolerance is
about 0.1 rpm; the rest is the walk's response to speed)."""


@pytest.fixture(scope="module")
def field_trials(tmp_path_factory):
    """A store with four real field trials (two legs, both floors) walked by a robot
    whose gait speed is `HIDDEN_SPEED_RPM`, and one simulated trial."""
    root = tmp_path_factory.mktemp("calibrate")
    uri = f"sqlite:///{root / 'mlflow.db'}"
    experiment = ensure_experiment(uri)
    config = load_config(sim_config())
    genomes = sim.random_genomes(np.random.default_rng(5), 3000)
    docs = []
    for i in np.argsort(sim.evaluate(genomes).loss):
        try:
            leg_from_genome(genomes[i])
        except LegError:
            continue
        doc = to_document(genomes[i])
        probe = FieldTrial("", doc, "flat", SECONDS, 0.0)
        if simulated_cm(config, [probe])[0] > 5.0:  # a leg that walks tells the speed
            docs.append(doc)
        if len(docs) == 2:
            break
    hidden = with_values(config, {"speed_rpm": HIDDEN_SPEED_RPM})
    runs = []
    for n, doc in enumerate(docs):
        for floor in ("flat", "carpet"):
            walked = simulated_cm(hidden, [FieldTrial("", doc, floor, SECONDS, 0.0)])[0]
            source = SourceLinkage(f"run{n}", None, experiment, "MAP-LIS", "Fp", doc, "")
            params = {"seconds": str(SECONDS), "repeats": "1", "simulated": REAL}
            runs.append(
                log_field_trial(
                    uri,
                    source,
                    robot="first",
                    floor=floor,
                    distances=[float(walked)],
                    params=params,
                )
            )
    source = SourceLinkage("runsim", None, experiment, "MAP-LIS", "Fp", docs[0], "")
    simulated = log_field_trial(
        uri,
        source,
        robot="first",
        floor="flat",
        distances=[1.0],
        params={"seconds": "2.0", "simulated": PHYSICS},
    )
    (root / "leg.json").write_text(json.dumps(docs[0]))
    return uri, runs, simulated, root


def sim_config():
    from linkevo.configs import shipped

    return shipped("hexapod.toml")


def test_calibration_recovers_the_hidden_speed_and_writes_a_config_commands_take(
    field_trials, tmp_path, capsys
):
    uri, runs, _, root = field_trials
    out = tmp_path / "calibrated.toml"
    argv = [
        "hexapod",
        "calibrate",
        "--trials",
        *runs,
        "--params",
        "speed_rpm",
        "--out",
        str(out),
        "--folds",
        "2",
        "--json",
        "--tracking-uri",
        uri,
    ]
    assert main(argv) == 0
    report = json.loads(capsys.readouterr().out)
    speed = report["params"]["speed_rpm"]
    assert abs(speed - HIDDEN_SPEED_RPM) <= TOLERANCE * HIDDEN_SPEED_RPM
    assert report["start"] == {"speed_rpm": 25.0} and report["trials"] == 4
    assert [t["run_id"] for t in report["per_trial"]] == runs
    assert report["heldout_rmse_cm"] < report["rmse_start_cm"]
    assert report["rmse_cm"] < report["rmse_start_cm"]
    written = load_config(out)
    assert written.gait.speed_rpm == speed
    assert written.physics == load_config(sim_config()).physics
    assert "calibrated by linkevo hexapod calibrate from 4 field trials" in out.read_text()
    assert tomllib.loads(out.read_text())["motors"]  # the rest of the base config is kept
    capsys.readouterr()
    code = main(
        [
            "hexapod",
            "simulate",
            "--linkage",
            str(root / "leg.json"),
            "--floor",
            "flat",
            "--seconds",
            str(SECONDS),
            "--repeats",
            "1",
            "--json",
            "--no-log",
            "--config",
            str(out),
            "--tracking-uri",
            uri,
        ]
    )
    assert code == 0
    walked = json.loads(capsys.readouterr().out)["mean_distance_cm"]
    hidden = with_values(load_config(sim_config()), {"speed_rpm": HIDDEN_SPEED_RPM})
    doc = json.loads((root / "leg.json").read_text())
    truth = simulated_cm(hidden, [FieldTrial("", doc, "flat", SECONDS, 0.0)])[0]
    assert walked == pytest.approx(truth, abs=1.0)


def test_simulated_runs_and_bad_names_are_refused_before_any_walk(field_trials, tmp_path, capsys):
    uri, runs, simulated, _ = field_trials
    out = tmp_path / "never.toml"
    base = ["hexapod", "calibrate", "--out", str(out), "--tracking-uri", uri]
    assert main([*base, "--trials", runs[0], simulated, "--params", "speed_rpm"]) == 2
    assert f"--trials {simulated}: a simulated field trial (simulated = physics)" in (
        capsys.readouterr().err
    )
    assert main([*base, "--trials", *runs[:2], "--params", "frame_mass"]) == 2
    err = capsys.readouterr().err
    assert "--params 'frame_mass': frame_mass; allowed: frame_mass_kg" in err
    assert main([*base, "--trials", runs[0], "--params", "speed_rpm"]) == 2
    assert "allowed: at least 2 distinct runs" in capsys.readouterr().err
    assert not out.exists()
