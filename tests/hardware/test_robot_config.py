"""Robot config loading: the study config, and clear errors for every kind of bad value."""

from __future__ import annotations

from pathlib import Path

import pytest

from linkevo.hardware.config import load_config, parse_config
from linkevo.sim.errors import ConfigError
from linkevo.sim.robot.hexapod import LEG_SLOTS, Robot
from tests.helpers.hexapod import raw_config, toml_text

REPO = Path(__file__).resolve().parents[2]


def test_study_config_has_six_motors_with_ids_4_and_6_reversed():
    config = load_config(REPO / "configs" / "hexapod.toml")
    assert config.motor_ids == [1, 2, 3, 4, 5, 6]
    assert [m.direction for m in config.motors] == [1, 1, 1, -1, 1, -1]
    assert {m.id for m in config.motors if m.phase_deg == 180.0} == {1, 2, 4}
    assert config.gait.rate_hz == 50.0
    assert config.bus.baudrate == 1_000_000


def test_config_file_round_trips(tmp_path):
    path = tmp_path / "robot.toml"
    path.write_text(toml_text(raw_config("/dev/null")), encoding="utf-8")
    config = load_config(path)
    assert config.bus.port == "/dev/null"
    assert config.motor(4).direction == -1 and config.motor(4).zero == 500
    assert config.with_port("/dev/pts/9").bus.port == "/dev/pts/9"


def _motor_change(**change):
    raw = raw_config("/dev/null")
    raw["motors"][2].update(change)
    return raw


@pytest.mark.parametrize(
    ("raw", "message"),
    [
        ({**raw_config("x"), "wheels": {}}, r"unknown section\(s\) \['wheels'\]"),
        (raw_config("x", gait={"rate": 50}), r"unknown key\(s\) \['rate'\] in test: \[gait\]"),
        (
            raw_config("x", gait={"rate_hz": "fast"}),
            r"\[gait\]\.rate_hz = 'fast' must be of type float",
        ),
        (
            raw_config("x", bus={"baudrate": 1e6}),
            r"\[bus\]\.baudrate = 1000000.0 must be of type int",
        ),
        (_motor_change(id=253), r"\[\[motors\]\] #3\.id = 253 is out of range \[0, 252\]"),
        (_motor_change(id=1), r"duplicate motor id\(s\) \[1\]"),
        (_motor_change(direction=0), r"#3\.direction = 0 is not allowed; choose one of \(1, -1\)"),
        (_motor_change(direction=True), r"#3\.direction = True must be of type int"),
        (_motor_change(phase_deg=360.0), r"#3\.phase_deg = 360.0 is out of range \[0.0, 360.0\)"),
        (_motor_change(zero=4096), r"#3\.zero = 4096 is out of range"),
        ({**raw_config("x"), "motors": []}, r"needs at least one \[\[motors\]\] entry"),
        (
            raw_config("x", safety={"on_hardware_error": "pray"}),
            r"choose one of \('stop', 'reboot'\)",
        ),
        (raw_config("x", safety={"min_voltage_v": 17.0}), r"min_voltage_v = 17.0 must be below"),
        (
            raw_config("x", mounting={"left-front": 1}),
            r"\[mounting\] names \['left-front'\]; give all six slots",
        ),
        (
            raw_config("x", mounting={**dict.fromkeys(LEG_SLOTS, 0), "left-rear": 9}),
            r"\[mounting\] left-rear = 9: allowed a whole number of layers, 0 to 8",
        ),
        (
            raw_config("x", mounting={**dict.fromkeys(LEG_SLOTS, 0), "left-rear": 1.5}),
            r"left-rear = 1.5: allowed a whole number",
        ),
    ],
)
def test_bad_values_are_named(raw, message):
    with pytest.raises(ConfigError, match=message):
        parse_config(raw, "test")


def test_missing_id_is_named():
    raw = raw_config("x")
    del raw["motors"][0]["id"]
    with pytest.raises(ConfigError, match=r"#1 is missing required key\(s\) \['id'\]"):
        parse_config(raw, "test")


def test_missing_file_and_bad_toml_are_named(tmp_path):
    with pytest.raises(ConfigError, match="does not exist"):
        load_config(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[bus\nport = 1", encoding="utf-8")
    with pytest.raises(ConfigError, match="is not valid TOML"):
        load_config(bad)


def test_a_mounting_section_fixes_every_legs_spacers_and_identifies_the_robot(tmp_path):
    spacers = {**dict.fromkeys(LEG_SLOTS, 0), "left-middle": 3, "right-middle": 3}
    path = tmp_path / "robot.toml"
    path.write_text(toml_text(raw_config("/dev/null", mounting=spacers)), encoding="utf-8")
    robot = load_config(path).robot()
    assert robot.spacers == spacers
    assert robot.changed()["mounting"] == spacers
    assert Robot.of(robot.changed()) == robot
    left_out = load_config(REPO / "configs" / "hexapod.toml").robot()
    assert left_out.spacers is None and "mounting" not in left_out.changed()
