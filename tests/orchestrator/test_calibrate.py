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

HIDDEN = {"speed_rpm": 19.0, "frame_mass_kg": 1.6, "carpet_friction": 0.6}
"""The robot the field trials are made by (the shipped config says 25 rpm, 1.1 kg, 0.9)."""
SECONDS = 2.0
TOLERANCE = 0.03
"""The calibrated speed is within 3 % of the hidden one."""
REPEATS, NOISE_CM = 3, 0.9
"""Each trial's repeats and their noise (a mean of three: about half a centimetre)."""


def walking_legs(config, count: int) -> list[dict]:
    """Documents of `count` random legs that walk forwards (a leg that walks tells the
    speed)."""
    genomes = sim.random_genomes(np.random.default_rng(5), 3000)
    docs = []
    for i in np.argsort(sim.evaluate(genomes).loss):
        try:
            leg_from_genome(genomes[i])
        except LegError:
            continue
        doc = to_document(genomes[i])
        if simulated_cm(config, [FieldTrial("", doc, "flat", SECONDS, 0.0)])[0] > 5.0:
            docs.append(doc)
        if len(docs) == count:
            return docs
    raise AssertionError("too few walking legs")


@pytest.fixture(scope="module")
def field_trials(tmp_path_factory):
    """A store with the real field trials of three legs, listed leg by leg, flat then
    carpet, walked by the hidden robot (`HIDDEN`) with noisy repeats; one simulated trial;
    and four legs the calibration never sees, for the error on unseen legs."""
    root = tmp_path_factory.mktemp("calibrate")
    uri = f"sqlite:///{root / 'mlflow.db'}"
    experiment = ensure_experiment(uri)
    config = load_config(sim_config())
    hidden = with_values(config, HIDDEN)
    docs = walking_legs(config, 7)
    noise = np.random.default_rng(1)
    runs = []
    for n, doc in enumerate(docs[:3]):
        for floor in ("flat", "carpet"):
            walked = simulated_cm(hidden, [FieldTrial("", doc, floor, SECONDS, 0.0)])[0]
            source = SourceLinkage(f"run{n}", None, experiment, "MAP-LIS", "Fp", doc, "")
            params = {"seconds": str(SECONDS), "repeats": str(REPEATS), "simulated": REAL}
            runs.append(
                log_field_trial(
                    uri,
                    source,
                    robot="first",
                    floor=floor,
                    distances=(walked + noise.normal(0, NOISE_CM, REPEATS)).tolist(),
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
    return uri, runs, simulated, root, docs[3:]


def sim_config():
    from linkevo.configs import shipped

    return shipped("hexapod.toml")


def test_calibration_finds_the_speed_says_what_it_cannot_and_predicts_unseen_legs(
    field_trials, tmp_path, capsys
):
    uri, runs, _, _, unseen = field_trials
    out = tmp_path / "calibrated.toml"
    argv = ["hexapod", "calibrate", "--trials", *runs, "--params", ",".join(HIDDEN)]
    assert main([*argv, "--out", str(out), "--json", "--tracking-uri", uri]) == 0
    report = json.loads(capsys.readouterr().out)
    speed = report["params"]["speed_rpm"]
    assert abs(speed - HIDDEN["speed_rpm"]) <= TOLERANCE * HIDDEN["speed_rpm"]
    assert "speed_rpm" in report["identified"]
    for name in ("frame_mass_kg", "carpet_friction"):  # what these trials barely see
        found = report["params"].get(name)
        assert name in report["not_identified"] or abs(found - HIDDEN[name]) <= 0.1 * HIDDEN[name]
    assert report["folds"] == 3 and report["trials"] == 6  # one fold per leg
    assert report["heldout_start_cm"] > report["heldout_rmse_cm"]
    # the reported prediction error is the error on legs the fit never saw (within 2x)
    written = load_config(out)
    hidden = with_values(load_config(sim_config()), HIDDEN)
    trials = [FieldTrial("", d, f, SECONDS, 0.0) for d in unseen for f in ("flat", "carpet")]
    truth = simulated_cm(hidden, trials) + np.random.default_rng(2).normal(0, 0.5, len(trials))
    error = float(np.sqrt(np.mean((simulated_cm(written, trials) - truth) ** 2)))
    assert 0.5 <= report["heldout_rmse_cm"] / error <= 2.0, (report["heldout_rmse_cm"], error)
    text = out.read_text()
    assert (
        "identified: speed_rpm" in text and "prediction error on legs the fit did not see" in text
    )
    for name in report["not_identified"]:  # left as they were, not marked calibrated
        assert f"{name} = " in text and not any(
            line.startswith(f"{name} =") and "calibrated" in line for line in text.splitlines()
        )
    assert written.gait.speed_rpm == speed
    assert tomllib.loads(text)["motors"]  # the rest of the base config is kept


def test_simulated_runs_and_bad_names_are_refused_before_any_walk(field_trials, tmp_path, capsys):
    uri, runs, simulated, _, _ = field_trials
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
    assert "allowed: at least 2 distinct runs of at least two legs" in capsys.readouterr().err
    assert main([*base, "--trials", *runs[:2], "--params", "speed_rpm"]) == 2  # one leg
    assert "every trial walked the same leg" in capsys.readouterr().err
    assert not out.exists()
