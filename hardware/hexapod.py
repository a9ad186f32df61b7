"""Provides Hexapod: start-up, alignment, the clock-timed tripod walk and the safe shutdown."""

from __future__ import annotations

import atexit
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from linkevo.hardware import control_table as ct
from linkevo.hardware.bus import DxlBus, Status
from linkevo.hardware.config import RobotConfig
from linkevo.hardware.errors import (
    AlignmentError,
    CommError,
    HardwareError,
    MotorNotResponding,
    WrongModel,
)
from linkevo.hardware.gait import PhaseController, alignment_goals
from linkevo.hardware.safety import REBOOT, SafetyMonitor
from linkevo.hardware.telemetry import TickRecord

_log = logging.getLogger(__name__)
_ALIGN_POLL_S = 0.02
_REBOOT_ANSWER_S = 1.0


@dataclass(frozen=True)
class WalkResult:
    """Summary of one walk.

    Attributes:
        ticks: control ticks completed (one telemetry row each).
        duration_s: wall time from the first tick to the end of the loop.
        skipped_ticks: slots dropped because the loop fell behind by more than max_lag_s.
        missed_reads: ticks whose sync read failed (tolerated up to max_missed_ticks in a row).
        reboots: motors rebooted by the hardware-error policy.
        watchdog_rearms: times the Bus Watchdog was cleared and set again because the
            loop had been silent for more than half its period (a stalled host).
        max_phase_error_rad: largest |phase error| of any leg after the first second.
        stopped_early: True when a stop was requested before the time was up.
    """

    ticks: int
    duration_s: float
    skipped_ticks: int
    missed_reads: int
    reboots: int
    watchdog_rearms: int
    max_phase_error_rad: float
    stopped_early: bool

    @property
    def rate_hz(self) -> float:
        """Returns the achieved tick rate."""
        return self.ticks / self.duration_s if self.duration_s > 0 else 0.0


class Hexapod:
    """Six (or any number of) MX-28 legs on one bus. Use as a context manager.

    Leaving the context (normally, on an exception, or at interpreter exit through
    `atexit`) runs `shutdown`: Goal Velocity 0, torque off on every motor, port closed.

    Args:
        config: the validated robot config.
        clock: monotonic seconds; the walk is timed against it.
    """

    def __init__(self, config: RobotConfig, *, clock: Callable[[], float] = time.monotonic) -> None:
        self.config = config
        self.bus = DxlBus(config.bus.port, config.bus.baudrate, latency_ms=config.bus.latency_ms)
        self._clock = clock
        self._ids = config.motor_ids
        self.velocity_limits = np.zeros(len(self._ids), dtype=int)
        self._watchdog = config.safety.bus_watchdog_ms // ct.BUS_WATCHDOG_MS_PER_UNIT
        self._open = False
        self.shutdown_problems: list[str] = []
        """What the last shutdown could not do (empty: every motor stopped, torque off)."""
        self._reached: set[int] = set()
        """Motors that answered their ping: only they can hold torque."""

    def __enter__(self) -> Hexapod:
        self.bus.open()
        self._open = True
        atexit.register(self.shutdown)
        return self

    def __exit__(self, *exc: object) -> None:
        self.shutdown_problems = self.shutdown()
        for problem in self.shutdown_problems:
            _log.error("shutdown: %s", problem)

    def _each(self, item: ct.Item, value: int) -> None:
        for motor_id in self._ids:
            self.bus.write(motor_id, item, value)

    def start_up(self) -> None:
        """Pings and checks every motor, then prepares them with torque off.

        Order per motor: ping (model 30), torque off, bus watchdog 0, return delay 0,
        read Velocity Limit, read Hardware Error Status (a set error stops here, unless
        the overload reboot policy applies), check the gait speed against the limit.

        Raises:
            MotorNotResponding: naming the motor that did not answer.
            WrongModel: naming the motor and the model it reported.
        """
        for motor in self.config.motors:
            model = self.bus.ping(motor.id)
            self._reached.add(motor.id)
            if model != ct.MX28_MODEL_NUMBER:
                raise WrongModel(
                    f"{motor.label} reports model {model}; expected MX-28(2.0), "
                    f"model {ct.MX28_MODEL_NUMBER}"
                )
        self._each(ct.TORQUE_ENABLE, 0)
        self._each(ct.BUS_WATCHDOG, 0)
        self._each(ct.RETURN_DELAY_TIME, 0)
        self.velocity_limits = np.array([self.bus.read(i, ct.VELOCITY_LIMIT) for i in self._ids])
        monitor = SafetyMonitor(self.config.safety, self.config.motors)
        for motor_id in self._ids:
            bits = self.bus.read(motor_id, ct.HARDWARE_ERROR_STATUS)
            if bits:
                monitor.on_hardware_error(0.0, motor_id, bits)
                self.bus.reboot(motor_id)
        needed = abs(ct.rpm_to_units(self.config.gait.speed_rpm))
        for motor, limit in zip(self.config.motors, self.velocity_limits, strict=True):
            if needed >= limit:
                raise HardwareError(
                    f"{motor.label}: gait speed {self.config.gait.speed_rpm:g} rpm needs "
                    f"{needed:.0f} units but its Velocity Limit is {limit}; lower [gait] speed_rpm"
                )

    def read_state(self, retries: int | None = None) -> dict[int, Status]:
        """Returns every motor's state block (126..146) from one sync read.

        Args:
            retries: extra attempts after a comm failure; None takes the bus's.
        """
        return self.bus.sync_read(ct.STATE_BLOCK, self._ids, retries=retries)

    def positions(self, statuses: dict[int, Status]) -> np.ndarray:
        """Returns (N,) Present Positions in config order."""
        return np.array([statuses[i].values[ct.PRESENT_POSITION.name] for i in self._ids])

    def align(self, stop: threading.Event | None = None) -> None:
        """Turns every leg to its phase offset in position mode, then drops torque.

        Does nothing when `stop` is already set: no torque goes on after a stop request.

        Raises:
            AlignmentError: naming the legs still off target after `[align] timeout_s`.
        """
        if stop is not None and stop.is_set():
            return
        align = self.config.align
        goals = alignment_goals(self.config.motors)
        self._each(ct.OPERATING_MODE, ct.POSITION_MODE)
        profile = max(1, round(ct.rpm_to_units(align.profile_velocity_rpm)))
        self._each(ct.PROFILE_VELOCITY, profile)
        self._each(ct.TORQUE_ENABLE, 1)
        self.bus.sync_write(ct.GOAL_POSITION, dict(zip(self._ids, goals.tolist(), strict=True)))
        tolerance = align.tolerance_deg / 360.0 * ct.POSITION_UNITS_PER_TURN
        deadline = self._clock() + align.timeout_s
        while True:
            off = np.abs(self.positions(self.read_state()) - goals)
            off = np.minimum(off % ct.POSITION_UNITS_PER_TURN, -off % ct.POSITION_UNITS_PER_TURN)
            if np.all(off <= tolerance) or (stop is not None and stop.is_set()):
                break
            if self._clock() > deadline:
                late = [
                    m.label for m, o in zip(self.config.motors, off, strict=True) if o > tolerance
                ]
                raise AlignmentError(
                    f"{', '.join(late)} did not reach the phase offset within "
                    f"{align.timeout_s:g} s (tolerance {align.tolerance_deg:g}°)"
                )
            time.sleep(_ALIGN_POLL_S)
        self._each(ct.TORQUE_ENABLE, 0)

    def _enter_velocity_mode(self, motor_ids: list[int]) -> None:
        for motor_id in motor_ids:
            self.bus.write(motor_id, ct.OPERATING_MODE, ct.VELOCITY_MODE)
            self.bus.write(motor_id, ct.GOAL_VELOCITY, 0)
            self.bus.write(motor_id, ct.TORQUE_ENABLE, 1)
            self.bus.write(motor_id, ct.BUS_WATCHDOG, self._watchdog)

    def _rearm_watchdog(self, silence_s: float) -> None:
        """Clears a Bus Watchdog that may have tripped (it then refuses goal writes and
        holds Goal Velocity 0) by writing 0, and sets it again."""
        _log.warning(
            "no goal write for %.0f ms (bus watchdog %d ms): re-arming the watchdog",
            silence_s * 1000.0,
            self._watchdog * ct.BUS_WATCHDOG_MS_PER_UNIT,
        )
        self.bus.sync_write(ct.BUS_WATCHDOG, dict.fromkeys(self._ids, 0))
        self.bus.sync_write(ct.BUS_WATCHDOG, dict.fromkeys(self._ids, self._watchdog))

    def _handle_alerts(self, monitor: SafetyMonitor, t: float, statuses: dict[int, Status]) -> int:
        """Decodes each alerting motor's Hardware Error Status; returns the reboots done."""
        reboots = 0
        for motor_id, status in statuses.items():
            if status.alert:
                bits = self.bus.read(motor_id, ct.HARDWARE_ERROR_STATUS)
                if monitor.on_hardware_error(t, motor_id, bits) == REBOOT:
                    self._reboot(motor_id)
                    reboots += 1
        return reboots

    def _reboot(self, motor_id: int) -> None:
        """Reboots one motor after an overload and puts it back in velocity mode."""
        self.bus.reboot(motor_id)
        deadline = self._clock() + _REBOOT_ANSWER_S
        while True:
            try:
                self.bus.ping(motor_id)
                break
            except MotorNotResponding:
                if self._clock() > deadline:
                    raise
        self._enter_velocity_mode([motor_id])

    def walk(
        self,
        seconds: float,
        *,
        on_tick: Callable[[TickRecord], None] | None = None,
        stop: threading.Event | None = None,
    ) -> WalkResult:
        """Walks for `seconds` on the fixed clock: per tick one sync read, one sync write.

        Tick k is due at `t0 + k / rate_hz`; a late tick runs at once, and only when the
        loop is more than `max_lag_s` behind are the missed slots skipped (and counted).
        When more than half the Bus Watchdog's period has passed since the last goal
        write, the watchdog may have tripped on a motor, so it is re-armed before the
        next goal write (and counted): a stalled host stops the legs only for the stall.

        A sync read that fails on the wire (no answer, or a corrupt or truncated status
        packet) costs its tick and is counted in `missed_reads`. A stop requested before
        the walk starts returns at once, before any motor is put in velocity mode.

        Raises:
            SafetyStop: a limit or hardware error (see `SafetyMonitor`).
            CommError: `max_missed_ticks` sync reads in a row failed (`MotorNotResponding`
                naming the motor when it did not answer).
        """
        gait, safety = self.config.gait, self.config.safety
        period = 1.0 / gait.rate_hz
        n_slots = max(1, round(seconds * gait.rate_hz))
        stop = stop or threading.Event()
        if stop.is_set():
            return WalkResult(0, 0.0, 0, 0, 0, 0, 0.0, stopped_early=True)
        controller = PhaseController(gait, self.config.motors, self.velocity_limits)
        monitor = SafetyMonitor(safety, self.config.motors)
        self._enter_velocity_mode(self._ids)
        ticks = skipped = missed = missed_in_row = reboots = rearms = 0
        max_error = 0.0
        watchdog_s = self._watchdog * ct.BUS_WATCHDOG_MS_PER_UNIT / 1000.0
        rearm_after_s = watchdog_s / 2 if watchdog_s else np.inf
        t0 = last_write = self._clock()
        controller.reset(t0)
        slot = 0
        while slot < n_slots and not stop.is_set():
            due = t0 + slot * period
            lag = self._clock() - due
            if lag < 0:
                stop.wait(-lag)
                continue
            if lag > gait.max_lag_s:
                behind = min(int(lag // period), n_slots - slot)
                skipped += behind
                slot += behind
                continue
            slot += 1
            now = self._clock()
            try:
                statuses = self.read_state(retries=0)  # a miss costs the tick, not a retry
            except CommError:
                missed += 1
                missed_in_row += 1
                self.bus.release()
                if missed_in_row >= safety.max_missed_ticks:
                    raise
                continue
            missed_in_row = 0
            monitor.check(now - t0, statuses)
            reboots += self._handle_alerts(monitor, now - t0, statuses)
            positions = self.positions(statuses)
            goals = controller.command(now, positions)
            if now - t0 >= 1.0:
                errors = np.abs(controller.phase_errors(now, positions))
                max_error = max(max_error, float(errors.max()))
            velocities = dict(zip(self._ids, goals.tolist(), strict=True))
            silence_s = self._clock() - last_write
            if silence_s > rearm_after_s:
                self._rearm_watchdog(silence_s)
                rearms += 1
            self.bus.sync_write(ct.GOAL_VELOCITY, velocities)
            last_write = self._clock()
            ticks += 1
            if on_tick is not None:
                on_tick(TickRecord(now - t0, statuses, velocities))
        if not stop.is_set():
            stop.wait(max(0.0, t0 + n_slots * period - self._clock()))
        return WalkResult(
            ticks=ticks,
            duration_s=self._clock() - t0,
            skipped_ticks=skipped,
            missed_reads=missed,
            reboots=reboots,
            watchdog_rearms=rearms,
            max_phase_error_rad=max_error,
            stopped_early=stop.is_set() and slot < n_slots,
        )

    def shutdown(self) -> list[str]:
        """Stops every motor: Goal Velocity 0, torque off, port closed. Idempotent.

        Every step is attempted even when an earlier one fails; each motor's Goal
        Velocity and Torque Enable are read back and logged, one line per motor (INFO:
        stopped; ERROR: what failed). The failures are returned, naming the motor, for
        every motor that answered at start-up (one that never answered cannot hold
        torque).
        """
        if not self._open:
            return []
        self._open = False
        atexit.unregister(self.shutdown)
        problems = []
        self.bus.release()
        # OSError covers a vanished adapter (pyserial's SerialException is one).
        try:
            self.bus.sync_write(ct.GOAL_VELOCITY, dict.fromkeys(self._ids, 0))
        except (HardwareError, OSError) as exc:
            problems.append(str(exc))
        names = {
            m.id: f"motor {m.id}" + (f" ({m.name})" if m.name else "") for m in self.config.motors
        }
        for motor_id in self._ids:
            try:
                self.bus.write(motor_id, ct.TORQUE_ENABLE, 0)
                velocity = self.bus.read(motor_id, ct.GOAL_VELOCITY)
                torque = self.bus.read(motor_id, ct.TORQUE_ENABLE)
            except (HardwareError, OSError) as exc:
                if motor_id in self._reached:
                    problems.append(f"torque off failed: {exc}")
                    _log.error("stop: %s: torque off failed: %s", names[motor_id], exc)
                continue
            if velocity == 0 and torque == 0:
                _log.info("stop: %s: Goal Velocity 0, torque off (read back)", names[motor_id])
            else:
                problem = (
                    f"{names[motor_id]} reads back Goal Velocity {velocity}, Torque Enable {torque}"
                )
                problems.append(problem)
                _log.error("stop: %s", problem)
        self.bus.close()
        return problems
