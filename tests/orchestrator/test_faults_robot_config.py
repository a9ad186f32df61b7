"""The robot config under faults, on every command that reads it: NaN and infinities,
folders and binary files, motors misnamed or missing, bad grid tables, refused before
any walk with one line naming what is wrong; and the config read whole ([gait] too)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from linkevo.configs import shipped
from linkevo.sim.robot.hexapod import FLOORS, Robot
from linkevo.sim.robot.walk_map import CellBatch, walk_cells
from tests.helpers.faults import refused, snapshot

LEG = str(Path(__file__).resolve().parents[1] / "data" / "sound_leg.json")


def robot_toml(tmp_path: Path, old: str, new: str) -> Path:
    """The shipped robot config with one line replaced."""
    text = shipped("hexapod.toml").read_text(encoding="utf-8")
    assert old in text, old
    path = tmp_path / "robot.toml"
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    return path


def commands(config: Path, out: Path) -> list[list[str]]:
    """Every command that walks with a robot config, asked to write into `out`."""
    store = f"sqlite:///{out / 'none.db'}"
    return [
        f"hexapod simulate --linkage {LEG} --floor flat --config {config} --no-log "
        f"--seconds 1 --repeats 1 --out {out}".split(),
        f"trial --approach MAP-LIS --fitness Fw --walks 2 --config {config} --out {out} "
        "--no-progress".split(),
        f"walkmap 0123456789abcdef --config {config} --tracking-uri {store}".split(),
    ]


@pytest.mark.parametrize(
    ("old", "new", "said"),
    [
        ("speed_rpm = 25.0", "speed_rpm = nan", "speed_rpm = nan is not a finite number"),
        ("kp = 10.0", "kp = inf", "kp = inf is not a finite number"),
        ("frame_mass_kg = 1.1", "frame_mass_kg = nan", "frame_mass_kg = nan is not a finite"),
        ("carpet_friction = 0.9", "carpet_friction = nan", "carpet_friction = nan is not a"),
    ],
)
def test_a_value_that_is_not_a_finite_number_is_refused_everywhere(
    tmp_path, capsys, old, new, said
):
    config = robot_toml(tmp_path, old, new)
    for argv in commands(config, tmp_path / "out"):
        assert said in refused(argv, capsys)
        assert snapshot(tmp_path / "out") == {}


def test_a_config_that_is_a_folder_or_not_text_is_refused(tmp_path, capsys):
    folder = tmp_path / "folder.toml"
    folder.mkdir()
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"\xff\xfe\x00gait")
    assert "is a folder; give a TOML file" in refused(commands(folder, tmp_path / "o")[0], capsys)
    assert "is not UTF-8 text" in refused(commands(binary, tmp_path / "o")[0], capsys)


@pytest.mark.parametrize(
    ("old", "new", "said"),
    [
        ('name = "left-front"', 'name = "front-left"', "a leg is mounted where its motor's name"),
        ('name = "left-front"', 'name = "left-middle"', "two motors share a name"),
    ],
)
def test_motors_that_are_not_the_six_slots_are_refused(tmp_path, capsys, old, new, said):
    config = robot_toml(tmp_path, old, new)
    for argv in commands(config, tmp_path / "out")[:2]:
        assert said in refused(argv, capsys)


def test_one_motor_is_refused_naming_the_slots(tmp_path, capsys):
    text = shipped("hexapod.toml").read_text(encoding="utf-8")
    first, *_ = text.split("[[motors]]")[1:]
    path = tmp_path / "one.toml"
    path.write_text(text.split("[[motors]]")[0] + "[[motors]]" + first, encoding="utf-8")
    said = refused(commands(path, tmp_path / "out")[0], capsys)
    assert "name the six left-front, left-middle" in said


@pytest.mark.parametrize(
    ("override", "said"),
    [
        ('walks="abc"', "'walks' = 'abc' is invalid: allowed: an integer >= 0"),
        ('walk_batch="abc"', "'walk_batch' = 'abc' is invalid: allowed: an integer >= 1"),
        ("physics={frame_mass_kg=nan}", "frame_mass_kg = nan is not a finite number"),
        ("gait={speed_rpm=nan}", "speed_rpm = nan is not a finite number"),
        ("gait={pace=2.0}", "gait: unknown key(s) ['pace']"),
        ("mounting={left-front=1}", "[mounting] names ['left-front']; give all six slots"),
    ],
)
def test_a_grids_bad_walking_keys_are_refused_by_their_key(tmp_path, capsys, override, said):
    store = f"sqlite:///{tmp_path / 'mlflow.db'}"
    argv = f"grid {shipped('walking.toml')} --dry-run --tracking-uri {store}".split()
    argv += ["--set", override]
    assert said in refused(argv, capsys)
    assert not (tmp_path / "mlflow.db").exists()


def test_a_calibrated_gait_speed_changes_a_walk_map_walk():
    """The walk map walks the robot whole: the same legs on a robot whose [gait] is half as
    fast walk a different, shorter distance."""
    import json

    from linkevo.sim.linkage.linkage_doc import from_document

    genome, mode = from_document(json.loads(Path(LEG).read_text()))
    batch = CellBatch(np.array([3]), genome[None], mode, ("flat",), seconds=2.0)
    study = walk_cells(batch)
    slow = walk_cells(batch, Robot.of({"gait": {"speed_rpm": 12.5}}))
    a, b = study[0]["mean_distance_cm"], slow[0]["mean_distance_cm"]
    assert math.isfinite(a) and math.isfinite(b)
    assert b < 0.8 * a
    assert set(FLOORS) >= {r["floor"] for r in study}
