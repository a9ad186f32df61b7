"""The simulated robot is the user's: `[physics]` of the robot config checked like every
config, carried by a grid and a trial, and the walks of an Fw trial walked on it."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import pandas as pd
import pytest

from linkevo.hardware.config import parse_config
from linkevo.orchestrator.cli import main
from linkevo.orchestrator.config import GridConfig
from linkevo.sim.errors import ConfigError
from linkevo.sim.robot.hexapod import FLOORS, LEG_SLOTS, Frame, Motor, Physics
from linkevo.workers.trial_spec import TrialSpec, TrialSpecError

SHIPPED = Path(__file__).parents[2] / "configs" / "hexapod.toml"


def test_the_shipped_physics_are_the_study_robots_estimates():
    config = parse_config(tomllib.loads(SHIPPED.read_text()))
    assert config.physics == Physics() and config.physics.changed() == {}
    assert config.physics.frame() == Frame() and config.physics.motor() == Motor()
    assert all(config.physics.floor(name) == FLOORS[name] for name in FLOORS)


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("frame_mass_kg", -1.0, "[physics].frame_mass_kg = -1.0 is out of range [0.1, 20.0]"),
        ("flat_friction", "slippery", "[physics].flat_friction = 'slippery' must be of type float"),
        ("frame_masss", 1.0, "unknown key(s) ['frame_masss'] in robot.toml: [physics]"),
    ],
)
def test_bad_physics_are_refused_naming_the_value(key, value, message):
    raw = tomllib.loads(SHIPPED.read_text())
    raw["physics"][key] = value
    with pytest.raises(ConfigError) as caught:
        parse_config(raw, "robot.toml")
    assert message in str(caught.value)


def test_a_grid_and_a_trial_carry_their_robot():
    walking = dict(approaches=("MAP-LIS",), fitnesses=("Fw",), walks=10)
    assert "physics" not in GridConfig(**walking).identity()
    heavy = GridConfig(**walking, physics={"frame_mass_kg": 2.5})
    assert heavy.identity()["physics"] == {"frame_mass_kg": 2.5}
    with pytest.raises(ConfigError, match="unknown key\\(s\\) \\['mass'\\]"):
        GridConfig(**walking, physics={"mass": 2.5})
    with pytest.raises(TrialSpecError, match=r"physics carpet_friction = 9\.0 is out of range"):
        TrialSpec.walking("MAP-LIS", 4, physics={"carpet_friction": 9.0})
    apart = {**dict.fromkeys(LEG_SLOTS, 0), "left-middle": 2, "right-middle": 2}
    mounted = GridConfig(**walking, mounting=apart)
    assert mounted.identity()["mounting"] == apart and "mounting" not in heavy.identity()
    assert TrialSpec.walking("MAP-LIS", 4, mounting=apart).robot().spacers == apart
    with pytest.raises(TrialSpecError, match=r"\[mounting\] left-rear = -1: allowed a whole"):
        TrialSpec.walking("MAP-LIS", 4, mounting={**apart, "left-rear": -1})


def test_an_fw_trial_walks_the_robot_its_config_describes(tmp_path):
    slippery = tmp_path / "slippery.toml"
    text = SHIPPED.read_text()
    slippery.write_text(text.replace("carpet_friction = 0.9", "carpet_friction = 0.05"))
    common = ["trial", "--approach", "MAP-LIS", "--fitness", "Fw", "--walks", "4", "--seed", "2"]
    assert main([*common, "--out", str(tmp_path / "study")]) == 0
    assert main([*common, "--out", str(tmp_path / "mine"), "--config", str(slippery)]) == 0
    spec = json.loads((tmp_path / "mine" / "settings.json").read_text())["spec"]
    assert spec["physics"] == {"carpet_friction": 0.05}
    study, mine = (pd.read_parquet(tmp_path / d / "walks.parquet") for d in ("study", "mine"))
    first = study.iteration == 1  # the first batch: the same legs in both trials
    assert (study.leg_key[first].to_numpy() == mine.leg_key[mine.iteration == 1].to_numpy()).all()
    carpet = [t.carpet_mean_distance_cm[t.iteration == 1].to_numpy() for t in (study, mine)]
    assert (carpet[0] != carpet[1]).any()  # the same legs, walked on another carpet
