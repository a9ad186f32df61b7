"""Shared fixtures for the hardware tests: a started bus emulator and robot configs."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from linkevo.hardware.config import RobotConfig, parse_config
from linkevo.hardware.emulator import BusEmulator
from tests.helpers.hexapod import TEST_IDS, raw_config, toml_text


@pytest.fixture
def emulator() -> Iterator[Callable[..., BusEmulator]]:
    """Returns a factory of started emulators; all are closed after the test."""
    started: list[BusEmulator] = []

    def make(motor_ids: list[int] = TEST_IDS, **kwargs: object) -> BusEmulator:
        emu = BusEmulator(motor_ids, **kwargs).start()
        started.append(emu)
        return emu

    yield make
    for emu in started:
        emu.close()


@pytest.fixture
def config_for() -> Callable[..., RobotConfig]:
    """Returns `make(port, **sections) -> RobotConfig` built from the test motors."""

    def make(port: str, **sections: dict) -> RobotConfig:
        return parse_config(raw_config(port, **sections), "test config")

    return make


@pytest.fixture
def config_file(tmp_path: Path) -> Callable[..., Path]:
    """Returns `make(port, **sections) -> Path` writing the test config as TOML."""

    def make(port: str, **sections: dict) -> Path:
        path = tmp_path / "robot.toml"
        path.write_text(toml_text(raw_config(port, **sections)), encoding="utf-8")
        return path

    return make
