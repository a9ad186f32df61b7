"""Provides RobotConfig: the hexapod's TOML config, loaded and validated with clear errors."""

from __future__ import annotations

import dataclasses
import math
import tomllib
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

from linkevo.hardware.control_table import POSITION_UNITS_PER_TURN
from linkevo.hardware.protocol import MAX_ID
from linkevo.sim.errors import ConfigError
from linkevo.sim.robot.gait import GaitConfig, limits, range_error
from linkevo.sim.robot.hexapod import Physics, Robot, check_spacers

T = TypeVar("T")


@dataclass(frozen=True)
class BusConfig:
    """Serial link: device path, baud rate and USB latency allowance."""

    port: str = "/dev/ttyUSB0"
    baudrate: int = 1_000_000
    latency_ms: float = field(default=16.0, metadata=limits(0.0, 1000.0))


@dataclass(frozen=True)
class AlignConfig:
    """Alignment to the phase offsets in position mode before walking."""

    profile_velocity_rpm: float = field(default=15.0, metadata=limits(0.3, 50.0))
    tolerance_deg: float = field(default=3.0, metadata=limits(0.1, 45.0))
    timeout_s: float = field(default=15.0, metadata=limits(0.1))


@dataclass(frozen=True)
class SafetyConfig:
    """Limits watched every tick and what to do on a hardware error (see docs/hardware.md)."""

    max_temperature_c: float = field(default=70.0, metadata=limits(0.0, 80.0))
    min_voltage_v: float = field(default=10.0, metadata=limits(0.0))
    max_voltage_v: float = field(default=16.0, metadata=limits(0.0))
    max_load_percent: float = field(default=90.0, metadata=limits(0.0, 100.0))
    load_hold_s: float = field(default=1.0, metadata=limits(0.0))
    on_hardware_error: str = field(default="stop", metadata={"choices": ("stop", "reboot")})
    max_reboots: int = field(default=3, metadata=limits(0))
    reboot_window_s: float = field(default=300.0, metadata=limits(0.0))
    bus_watchdog_ms: int = field(default=200, metadata=limits(0, 2540))
    max_missed_ticks: int = field(default=3, metadata=limits(1))


@dataclass(frozen=True)
class MotorConfig:
    """One leg's motor: id, mounting direction, tripod phase offset and calibrated zero."""

    id: int = field(metadata=limits(0, MAX_ID))
    name: str = ""
    direction: int = field(default=1, metadata={"choices": (1, -1)})
    phase_deg: float = field(default=0.0, metadata=limits(0.0, 360.0, open_high=True))
    zero: int = field(default=0, metadata=limits(0, POSITION_UNITS_PER_TURN - 1))

    @property
    def label(self) -> str:
        """Returns 'motor 3 (right-middle)' style text for messages."""
        return f"motor {self.id} ({self.name})" if self.name else f"motor {self.id}"

    @property
    def phase_rad(self) -> float:
        return math.radians(self.phase_deg)


@dataclass(frozen=True)
class RobotConfig:
    """The whole robot config (one TOML file)."""

    bus: BusConfig
    gait: GaitConfig
    align: AlignConfig
    safety: SafetyConfig
    motors: tuple[MotorConfig, ...]
    physics: Physics = field(default_factory=Physics)
    mounting: dict[str, int] | None = None

    @property
    def motor_ids(self) -> list[int]:
        return [m.id for m in self.motors]

    def motor(self, motor_id: int) -> MotorConfig:
        """Returns the config of the motor with this id."""
        return next(m for m in self.motors if m.id == motor_id)

    def robot(self) -> Robot:
        """Returns the robot a simulated walk walks, whole: its `[physics]`, its `[gait]`,
        each leg's phase offset from its motor's `name` (the slot, `sim.robot.hexapod.LEG_SLOTS`)
        and `phase_deg`, and its `[mounting]` (the one loader of every command that walks).

        Raises:
            ConfigError: the motors are not the six slots, named once each.
        """
        phases = {m.name: m.phase_deg for m in self.motors}
        try:
            if len(phases) != len(self.motors):
                raise ValueError(f"two motors share a name among {[m.name for m in self.motors]}")
            return Robot(self.physics, self.gait, phases, self.mounting)
        except ValueError as exc:
            raise ConfigError(f"robot config: {exc}") from None

    def with_port(self, port: str) -> RobotConfig:
        """Returns a copy that talks to another serial port (e.g. the emulator's pty)."""
        return dataclasses.replace(self, bus=dataclasses.replace(self.bus, port=port))


_SECTIONS = {
    "bus": BusConfig,
    "gait": GaitConfig,
    "align": AlignConfig,
    "safety": SafetyConfig,
    "physics": Physics,
}
_TYPES = {"int": (int,), "float": (int, float), "str": (str,)}


def _build(cls: type[T], raw: object, where: str) -> T:
    """Returns `cls(**raw)` after checking keys, types and ranges, naming any bad value."""
    if not isinstance(raw, dict):
        raise ConfigError(f"{where} must be a table, got {type(raw).__name__}")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(raw) - set(fields))
    if unknown:
        raise ConfigError(f"unknown key(s) {unknown} in {where}; allowed: {sorted(fields)}")
    hints = typing.get_type_hints(cls)
    for name, value in raw.items():
        key = f"{where}.{name}"
        allowed = _TYPES[hints[name].__name__]
        if isinstance(value, bool) or not isinstance(value, allowed):
            raise ConfigError(f"{key} = {value!r} must be of type {hints[name].__name__}")
        meta = fields[name].metadata
        if "choices" in meta and value not in meta["choices"]:
            raise ConfigError(f"{key} = {value!r} is not allowed; choose one of {meta['choices']}")
        wrong = range_error(key, value, meta) if "low" in meta else None
        if wrong:
            raise ConfigError(wrong)
    missing = [
        n
        for n, f in fields.items()
        if n not in raw
        and f.default is dataclasses.MISSING
        and f.default_factory is dataclasses.MISSING
    ]
    if missing:
        raise ConfigError(f"{where} is missing required key(s) {missing}")
    return cls(**{n: float(v) if hints[n].__name__ == "float" else v for n, v in raw.items()})


def parse_config(raw: dict, source: str = "config") -> RobotConfig:
    """Returns the validated RobotConfig from a parsed TOML document.

    Raises:
        ConfigError: naming the bad key or value and what is allowed.
    """
    allowed = {*_SECTIONS, "motors", "mounting"}
    unknown = sorted(set(raw) - allowed)
    if unknown:
        raise ConfigError(f"{source}: unknown section(s) {unknown}; allowed: {sorted(allowed)}")
    sections = {
        name: _build(cls, raw.get(name, {}), f"{source}: [{name}]")
        for name, cls in _SECTIONS.items()
    }
    motors_raw = raw.get("motors")
    if not isinstance(motors_raw, list) or not motors_raw:
        raise ConfigError(f"{source}: needs at least one [[motors]] entry")
    motors = tuple(
        _build(MotorConfig, m, f"{source}: [[motors]] #{i + 1}") for i, m in enumerate(motors_raw)
    )
    ids = [m.id for m in motors]
    duplicates = sorted({i for i in ids if ids.count(i) > 1})
    if duplicates:
        raise ConfigError(f"{source}: duplicate motor id(s) {duplicates}; each id must be unique")
    safety = sections["safety"]
    if safety.min_voltage_v >= safety.max_voltage_v:
        raise ConfigError(
            f"{source}: [safety] min_voltage_v = {safety.min_voltage_v} must be below "
            f"max_voltage_v = {safety.max_voltage_v}"
        )
    mounting = raw.get("mounting")
    if mounting is not None:
        if not isinstance(mounting, dict):
            raise ConfigError(
                f"{source}: [mounting] must be a table, got {type(mounting).__name__}"
            )
        try:
            check_spacers(mounting)
        except ValueError as exc:
            raise ConfigError(f"{source}: {exc}") from None
    return RobotConfig(motors=motors, mounting=mounting, **sections)


def load_config(path: str | Path) -> RobotConfig:
    """Returns the validated RobotConfig read from a TOML file.

    Raises:
        ConfigError: when the file is missing, not TOML, or holds a bad value.
    """
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise ConfigError(f"robot config {str(path)!r} does not exist") from exc
    except IsADirectoryError as exc:
        raise ConfigError(f"robot config {str(path)!r} is a folder; give a TOML file") from exc
    except OSError as exc:
        raise ConfigError(f"robot config {str(path)!r} cannot be read ({exc.strerror})") from exc
    except UnicodeDecodeError as exc:
        raise ConfigError(f"robot config {str(path)!r} is not UTF-8 text (TOML)") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"robot config {str(path)!r} is not valid TOML: {exc}") from exc
    return parse_config(raw, str(path))
