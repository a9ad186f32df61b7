"""Provides the MX-28AT Protocol 2.0 control table (model 30) and its unit conversions."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

MX28_MODEL_NUMBER = 30
POSITION_UNITS_PER_TURN = 4096
VELOCITY_RPM_PER_UNIT = 0.229
LOAD_PERCENT_PER_UNIT = 0.1
VOLTAGE_V_PER_UNIT = 0.1
BUS_WATCHDOG_MS_PER_UNIT = 20
EEPROM_END = 64
"""Addresses below this are EEPROM: writable only while torque is off."""

VELOCITY_MODE = 1
POSITION_MODE = 3
EXTENDED_POSITION_MODE = 4


@dataclass(frozen=True)
class Item:
    """One control-table entry: where it lives, how wide it is and how to read it."""

    name: str
    address: int
    size: int
    signed: bool = False
    writable: bool = True


MODEL_NUMBER = Item("model_number", 0, 2, writable=False)
FIRMWARE_VERSION = Item("firmware_version", 6, 1, writable=False)
ID = Item("id", 7, 1)
BAUD_RATE = Item("baud_rate", 8, 1)
RETURN_DELAY_TIME = Item("return_delay_time", 9, 1)
DRIVE_MODE = Item("drive_mode", 10, 1)
OPERATING_MODE = Item("operating_mode", 11, 1)
HOMING_OFFSET = Item("homing_offset", 20, 4, signed=True)
TEMPERATURE_LIMIT = Item("temperature_limit", 31, 1)
MAX_VOLTAGE_LIMIT = Item("max_voltage_limit", 32, 2)
MIN_VOLTAGE_LIMIT = Item("min_voltage_limit", 34, 2)
VELOCITY_LIMIT = Item("velocity_limit", 44, 4)
SHUTDOWN = Item("shutdown", 63, 1)
TORQUE_ENABLE = Item("torque_enable", 64, 1)
STATUS_RETURN_LEVEL = Item("status_return_level", 68, 1)
HARDWARE_ERROR_STATUS = Item("hardware_error_status", 70, 1, writable=False)
BUS_WATCHDOG = Item("bus_watchdog", 98, 1, signed=True)
GOAL_VELOCITY = Item("goal_velocity", 104, 4, signed=True)
PROFILE_VELOCITY = Item("profile_velocity", 112, 4)
GOAL_POSITION = Item("goal_position", 116, 4, signed=True)
MOVING = Item("moving", 122, 1, writable=False)
PRESENT_LOAD = Item("present_load", 126, 2, signed=True, writable=False)
PRESENT_VELOCITY = Item("present_velocity", 128, 4, signed=True, writable=False)
PRESENT_POSITION = Item("present_position", 132, 4, signed=True, writable=False)
VELOCITY_TRAJECTORY = Item("velocity_trajectory", 136, 4, signed=True, writable=False)
POSITION_TRAJECTORY = Item("position_trajectory", 140, 4, signed=True, writable=False)
PRESENT_INPUT_VOLTAGE = Item("present_input_voltage", 144, 2, writable=False)
PRESENT_TEMPERATURE = Item("present_temperature", 146, 1, writable=False)

ITEMS = (
    MODEL_NUMBER,
    FIRMWARE_VERSION,
    ID,
    BAUD_RATE,
    RETURN_DELAY_TIME,
    DRIVE_MODE,
    OPERATING_MODE,
    HOMING_OFFSET,
    TEMPERATURE_LIMIT,
    MAX_VOLTAGE_LIMIT,
    MIN_VOLTAGE_LIMIT,
    VELOCITY_LIMIT,
    SHUTDOWN,
    TORQUE_ENABLE,
    STATUS_RETURN_LEVEL,
    HARDWARE_ERROR_STATUS,
    BUS_WATCHDOG,
    GOAL_VELOCITY,
    PROFILE_VELOCITY,
    GOAL_POSITION,
    MOVING,
    PRESENT_LOAD,
    PRESENT_VELOCITY,
    PRESENT_POSITION,
    VELOCITY_TRAJECTORY,
    POSITION_TRAJECTORY,
    PRESENT_INPUT_VOLTAGE,
    PRESENT_TEMPERATURE,
)

STATE_BLOCK = (
    PRESENT_LOAD,
    PRESENT_VELOCITY,
    PRESENT_POSITION,
    VELOCITY_TRAJECTORY,
    POSITION_TRAJECTORY,
    PRESENT_INPUT_VOLTAGE,
    PRESENT_TEMPERATURE,
)
"""The contiguous span 126..146 (21 bytes) read once per tick."""

HARDWARE_ERROR_BITS = {
    0: "input voltage",
    2: "overheating",
    3: "motor encoder",
    4: "electrical shock",
    5: "overload",
}
"""Hardware Error Status (address 70) bit -> meaning."""
OVERLOAD_BIT = 5


def block_span(items: tuple[Item, ...]) -> tuple[int, int]:
    """Returns (start address, length in bytes) of a contiguous run of items."""
    start = items[0].address
    for before, after in itertools.pairwise(items):
        if before.address + before.size != after.address:
            raise ValueError(f"items {before.name} and {after.name} are not contiguous")
    return start, items[-1].address + items[-1].size - start


def to_signed(value: int, size: int) -> int:
    """Returns the two's-complement reading of an unsigned `size`-byte value."""
    bits = 8 * size
    value &= (1 << bits) - 1
    return value - (1 << bits) if value >= 1 << (bits - 1) else value


def to_unsigned(value: int, size: int) -> int:
    """Returns the `size`-byte two's-complement encoding of a signed value.

    Raises:
        ValueError: when the value does not fit in `size` bytes.
    """
    bits = 8 * size
    if not -(1 << (bits - 1)) <= value < (1 << bits):
        raise ValueError(f"value {value} does not fit in {size} byte(s)")
    return value & ((1 << bits) - 1)


def decode(item: Item, data: bytes, start: int) -> int:
    """Returns the item's value from little-endian bytes that begin at address `start`."""
    offset = item.address - start
    raw = int.from_bytes(data[offset : offset + item.size], "little")
    return to_signed(raw, item.size) if item.signed else raw


def encode(item: Item, value: int) -> bytes:
    """Returns the item's little-endian bytes for a (possibly negative) value."""
    return to_unsigned(value, item.size).to_bytes(item.size, "little")


def rpm_to_units(rpm: float) -> float:
    """Returns a velocity in 0.229 rpm units."""
    return rpm / VELOCITY_RPM_PER_UNIT


def units_to_rpm(units: float) -> float:
    """Returns a velocity in rpm from 0.229 rpm units."""
    return units * VELOCITY_RPM_PER_UNIT


def hardware_error_names(bits: int) -> list[str]:
    """Returns the names of the Hardware Error Status bits that are set."""
    return [name for bit, name in HARDWARE_ERROR_BITS.items() if bits & (1 << bit)]
