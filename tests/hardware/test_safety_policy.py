"""SafetyMonitor: the documented limits and the rate-limited overload reboot (pure)."""

from __future__ import annotations

import pytest

from linkevo.hardware import control_table as ct
from linkevo.hardware.bus import Status
from linkevo.hardware.config import MotorConfig, SafetyConfig
from linkevo.hardware.errors import SafetyStop
from linkevo.hardware.safety import REBOOT, SafetyMonitor

MOTORS = (MotorConfig(id=1, name="left-front"), MotorConfig(id=2))


def status(load=100, volts=12.0, temperature=35):
    values = {
        ct.PRESENT_LOAD.name: load,
        ct.PRESENT_INPUT_VOLTAGE.name: round(volts * 10),
        ct.PRESENT_TEMPERATURE.name: temperature,
    }
    return Status(values, alert=False)


def test_readings_within_limits_pass():
    SafetyMonitor(SafetyConfig(), MOTORS).check(0.0, {1: status(), 2: status(load=-800)})


@pytest.mark.parametrize(
    ("reading", "message"),
    [
        (
            status(temperature=70),
            r"^motor 1 \(left-front\): temperature 70 °C reached the limit 70",
        ),
        (status(volts=9.5), r"supply voltage 9.5 V is outside \[10, 16\] V"),
        (status(volts=16.6), r"supply voltage 16.6 V is outside"),
    ],
)
def test_a_breach_stops_at_once(reading, message):
    with pytest.raises(SafetyStop, match=message):
        SafetyMonitor(SafetyConfig(), MOTORS).check(0.0, {1: reading})


def test_load_must_stay_high_for_the_hold_time():
    monitor = SafetyMonitor(SafetyConfig(max_load_percent=90.0, load_hold_s=1.0), MOTORS)
    monitor.check(0.0, {2: status(load=-950)})
    monitor.check(0.5, {2: status(load=-950)})
    monitor.check(0.6, {2: status(load=100)})
    monitor.check(1.2, {2: status(load=950)})
    with pytest.raises(SafetyStop, match=r"^motor 2: load 95.0 % stayed above 90 % for 1.00 s"):
        monitor.check(2.2, {2: status(load=950)})


def test_hardware_errors_stop_under_the_default_policy():
    monitor = SafetyMonitor(SafetyConfig(), MOTORS)
    with pytest.raises(SafetyStop, match="hardware error: overload"):
        monitor.on_hardware_error(0.0, 1, 1 << ct.OVERLOAD_BIT)


def test_reboot_policy_covers_overload_only_and_is_rate_limited():
    safety = SafetyConfig(on_hardware_error="reboot", max_reboots=2, reboot_window_s=10.0)
    monitor = SafetyMonitor(safety, MOTORS)
    with pytest.raises(SafetyStop, match="hardware error: overheating, overload"):
        monitor.on_hardware_error(0.0, 1, 0b100100)
    assert monitor.on_hardware_error(1.0, 1, 1 << ct.OVERLOAD_BIT) == REBOOT
    assert monitor.on_hardware_error(2.0, 2, 1 << ct.OVERLOAD_BIT) == REBOOT
    with pytest.raises(SafetyStop, match=r"already rebooted 2 times in 10 s"):
        monitor.on_hardware_error(3.0, 1, 1 << ct.OVERLOAD_BIT)
    assert monitor.on_hardware_error(11.5, 1, 1 << ct.OVERLOAD_BIT) == REBOOT
