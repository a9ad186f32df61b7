"""Provides the safety policy (SafetyMonitor) and SignalGuard (SIGINT/SIGTERM become a stop).

Policy (also in docs/hardware.md): a temperature at or above the limit, a supply voltage
outside its band, or a load above its limit for longer than the hold time stops the walk.
A hardware error (alert bit in a status packet, decoded from address 70) stops the walk,
except that with `on_hardware_error = "reboot"` an overload-only error reboots the motor,
at most `max_reboots` times per `reboot_window_s`.
"""

from __future__ import annotations

import collections
import signal
import threading
from collections.abc import Mapping

from linkevo.hardware import control_table as ct
from linkevo.hardware.bus import Status
from linkevo.hardware.config import MotorConfig, SafetyConfig
from linkevo.hardware.errors import SafetyStop

REBOOT = "reboot"


class SafetyMonitor:
    """Checks every tick's readings against the limits; raises SafetyStop on a breach.

    Args:
        safety: limits and hardware-error policy.
        motors: the configured motors (names are used in messages).
    """

    def __init__(self, safety: SafetyConfig, motors: tuple[MotorConfig, ...]) -> None:
        self._safety = safety
        self._labels = {m.id: m.label for m in motors}
        self._overload_since: dict[int, float] = {}
        self._reboots: collections.deque[float] = collections.deque()

    def _stop(self, motor_id: int, what: str) -> SafetyStop:
        return SafetyStop(
            f"{self._labels.get(motor_id, f'motor {motor_id}')}: {what}; walk stopped",
            motor_id=motor_id,
        )

    def check(self, t: float, statuses: Mapping[int, Status]) -> None:
        """Raises SafetyStop when a reading breaks a limit at time `t` (seconds)."""
        s = self._safety
        for motor_id, status in statuses.items():
            v = status.values
            temperature = v[ct.PRESENT_TEMPERATURE.name]
            if temperature >= s.max_temperature_c:
                raise self._stop(
                    motor_id,
                    f"temperature {temperature} °C reached the limit {s.max_temperature_c:g} °C",
                )
            volts = v[ct.PRESENT_INPUT_VOLTAGE.name] * ct.VOLTAGE_V_PER_UNIT
            if not s.min_voltage_v <= volts <= s.max_voltage_v:
                raise self._stop(
                    motor_id,
                    f"supply voltage {volts:.1f} V is outside "
                    f"[{s.min_voltage_v:g}, {s.max_voltage_v:g}] V",
                )
            load = abs(v[ct.PRESENT_LOAD.name]) * ct.LOAD_PERCENT_PER_UNIT
            if load <= s.max_load_percent:
                self._overload_since.pop(motor_id, None)
                continue
            since = self._overload_since.setdefault(motor_id, t)
            if t - since >= s.load_hold_s:
                raise self._stop(
                    motor_id,
                    f"load {load:.1f} % stayed above {s.max_load_percent:g} % "
                    f"for {t - since:.2f} s",
                )

    def on_hardware_error(self, t: float, motor_id: int, bits: int) -> str:
        """Returns REBOOT when policy allows a reboot for these error bits, else raises.

        Raises:
            SafetyStop: naming the motor and the decoded error bits.
        """
        s = self._safety
        names = ", ".join(ct.hardware_error_names(bits)) or f"bits {bits:#04x}"
        while self._reboots and t - self._reboots[0] > s.reboot_window_s:
            self._reboots.popleft()
        overload_only = bits == 1 << ct.OVERLOAD_BIT
        if s.on_hardware_error == REBOOT and overload_only:
            if len(self._reboots) < s.max_reboots:
                self._reboots.append(t)
                return REBOOT
            names += f" (already rebooted {s.max_reboots} times in {s.reboot_window_s:g} s)"
        raise self._stop(motor_id, f"hardware error: {names}")


class SignalGuard:
    """Context manager: SIGINT and SIGTERM set `event` instead of killing the process.

    The control loop checks `event` every tick and leaves through the normal shutdown
    path, so a signal never interrupts a transaction half-way. Outside the main thread
    (where handlers cannot be installed) it only provides the event.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.event = threading.Event()
        self.signal_name: str | None = None
        self._previous: dict[int, object] = {}

    def _handle(self, signum: int, frame: object) -> None:
        self.signal_name = signal.Signals(signum).name
        self.event.set()

    def __enter__(self) -> SignalGuard:
        if threading.current_thread() is threading.main_thread():
            for sig in self.SIGNALS:
                self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()
