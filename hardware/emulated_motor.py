"""Provides EmulatedMotor: one stateful MX-28(2.0) control table with simple physics."""

from __future__ import annotations

from dataclasses import dataclass

from linkevo.hardware import control_table as ct

_TABLE_SIZE = 147
_DEFAULTS = {
    ct.MODEL_NUMBER: ct.MX28_MODEL_NUMBER,
    ct.FIRMWARE_VERSION: 45,
    ct.BAUD_RATE: 1,
    ct.RETURN_DELAY_TIME: 250,
    ct.OPERATING_MODE: ct.POSITION_MODE,
    ct.TEMPERATURE_LIMIT: 80,
    ct.MAX_VOLTAGE_LIMIT: 160,
    ct.MIN_VOLTAGE_LIMIT: 95,
    ct.SHUTDOWN: 52,
    ct.STATUS_RETURN_LEVEL: 2,
}
_OPERATING_MODES = (ct.VELOCITY_MODE, ct.POSITION_MODE, ct.EXTENDED_POSITION_MODE, 16)
_UNITS_PER_S_PER_VELOCITY_UNIT = ct.VELOCITY_RPM_PER_UNIT / 60.0 * ct.POSITION_UNITS_PER_TURN
_GOALS = (ct.GOAL_VELOCITY, ct.GOAL_POSITION)
_FULL_SPEED_LOAD = 200
"""Present Load (0.1 %) reported at the velocity limit, before any injected extra load."""

DATA_RANGE_ERROR = 4
DATA_LIMIT_ERROR = 6
ACCESS_ERROR = 7


@dataclass(frozen=True)
class MotorSnapshot:
    """What a test can inspect of one emulated motor."""

    motor_id: int
    torque_enabled: bool
    operating_mode: int
    goal_velocity: int
    present_velocity: int
    position: int
    temperature: int
    hardware_error: int
    bus_watchdog: int
    return_delay_time: int


class EmulatedMotor:
    """An MX-28AT in Protocol 2.0: control table, EEPROM lock, shutdown, bus watchdog.

    Time is passed in explicitly (`now`, seconds); the motor integrates its velocity
    between calls, so position advances with real elapsed time, not with packets.
    """

    def __init__(
        self,
        motor_id: int,
        *,
        now: float,
        velocity_limit: int = 230,
        model_number: int = ct.MX28_MODEL_NUMBER,
    ) -> None:
        self.motor_id = motor_id
        self.table = bytearray(_TABLE_SIZE)
        for item, value in _DEFAULTS.items():
            self._store(item, value)
        self._store(ct.ID, motor_id)
        self._store(ct.VELOCITY_LIMIT, velocity_limit)
        self._store(ct.MODEL_NUMBER, model_number)
        self.position = 0.0
        self.temperature = 30.0
        self.heating_c_per_s = 0.0
        self.voltage = 12.0
        self.last_update = now
        self.last_packet = now

    def value(self, item: ct.Item) -> int:
        """Returns the item's current (signed where the item is signed) value."""
        return ct.decode(item, self.table, 0)

    def _store(self, item: ct.Item, value: int) -> None:
        self.table[item.address : item.address + item.size] = ct.encode(item, value)

    @property
    def torque_on(self) -> bool:
        return self.value(ct.TORQUE_ENABLE) == 1

    @property
    def hardware_error(self) -> int:
        return self.value(ct.HARDWARE_ERROR_STATUS)

    def set_hardware_error(self, bits: int) -> None:
        """Raises hardware error bits; torque drops when one is in the Shutdown mask."""
        self._store(ct.HARDWARE_ERROR_STATUS, self.hardware_error | bits)
        if bits & self.value(ct.SHUTDOWN):
            self._store(ct.TORQUE_ENABLE, 0)

    def _velocity(self) -> float:
        """Returns the current shaft velocity in 0.229 rpm units."""
        if not self.torque_on:
            return 0.0
        mode = self.value(ct.OPERATING_MODE)
        if mode == ct.VELOCITY_MODE:
            return float(self.value(ct.GOAL_VELOCITY))
        if mode in (ct.POSITION_MODE, ct.EXTENDED_POSITION_MODE):
            error = self.value(ct.GOAL_POSITION) - self.position
            if abs(error) < 0.5:
                return 0.0
            speed = self.value(ct.PROFILE_VELOCITY) or self.value(ct.VELOCITY_LIMIT)
            return speed if error > 0 else -speed
        return 0.0

    def _integrate(self, dt: float) -> None:
        velocity = self._velocity()
        step = velocity * _UNITS_PER_S_PER_VELOCITY_UNIT * dt
        if self.value(ct.OPERATING_MODE) != ct.VELOCITY_MODE and velocity != 0.0:
            remaining = self.value(ct.GOAL_POSITION) - self.position
            step = max(-abs(remaining), min(abs(remaining), step))
        self.position += step
        self.temperature += self.heating_c_per_s * dt
        if self.temperature > self.value(ct.TEMPERATURE_LIMIT):
            self.set_hardware_error(1 << 2)

    def advance(self, now: float) -> None:
        """Integrates motion, heating and the bus watchdog up to `now`."""
        watchdog = self.value(ct.BUS_WATCHDOG)
        if self.torque_on and watchdog > 0:
            trip = self.last_packet + watchdog * ct.BUS_WATCHDOG_MS_PER_UNIT / 1000.0
            if trip < now:
                self._integrate(max(0.0, trip - self.last_update))
                self.last_update = max(self.last_update, trip)
                self._store(ct.GOAL_VELOCITY, 0)
                self._store(ct.BUS_WATCHDOG, -1)
        self._integrate(now - self.last_update)
        self.last_update = now
        self._refresh_present(self._velocity())

    def _refresh_present(self, velocity: float) -> None:
        limit = max(1, self.value(ct.VELOCITY_LIMIT))
        load = round(velocity / limit * _FULL_SPEED_LOAD)
        self._store(ct.PRESENT_VELOCITY, round(velocity))
        self._store(ct.VELOCITY_TRAJECTORY, round(velocity))
        self._store(ct.PRESENT_POSITION, round(self.position))
        self._store(ct.POSITION_TRAJECTORY, round(self.position))
        self._store(ct.PRESENT_LOAD, max(-1000, min(1000, load)))
        self._store(ct.PRESENT_INPUT_VOLTAGE, round(self.voltage * 10))
        self._store(ct.PRESENT_TEMPERATURE, round(self.temperature))
        self._store(ct.MOVING, int(velocity != 0.0))

    def read(self, address: int, length: int) -> tuple[int, bytes]:
        """Returns (error number, data) for a READ of `length` bytes at `address`."""
        if length == 0 or address + length > _TABLE_SIZE:
            return DATA_RANGE_ERROR, b""
        return 0, bytes(self.table[address : address + length])

    def write(self, address: int, data: bytes) -> int:
        """Applies a WRITE and returns its error number (0 when accepted)."""
        end = address + len(data)
        if not data or end > _TABLE_SIZE:
            return DATA_RANGE_ERROR
        touched = [it for it in ct.ITEMS if it.address < end and address < it.address + it.size]
        if any(not it.writable for it in touched):
            return ACCESS_ERROR
        if address < ct.EEPROM_END and self.torque_on:
            return ACCESS_ERROR
        if self.value(ct.BUS_WATCHDOG) == -1 and any(it in _GOALS for it in touched):
            return ACCESS_ERROR
        staged = bytearray(self.table)
        staged[address:end] = data
        error = self._check(staged, touched)
        if error:
            return error
        self._apply(staged, touched)
        return 0

    def _check(self, staged: bytearray, touched: list[ct.Item]) -> int:
        def new(item: ct.Item) -> int:
            return ct.decode(item, staged, 0)

        limit = new(ct.VELOCITY_LIMIT)
        checks = {
            ct.GOAL_VELOCITY: lambda: abs(new(ct.GOAL_VELOCITY)) <= limit,
            ct.VELOCITY_LIMIT: lambda: 0 <= limit <= 1023,
            ct.OPERATING_MODE: lambda: new(ct.OPERATING_MODE) in _OPERATING_MODES,
            ct.TORQUE_ENABLE: lambda: new(ct.TORQUE_ENABLE) in (0, 1),
            ct.BUS_WATCHDOG: lambda: 0 <= new(ct.BUS_WATCHDOG) <= 127,
            ct.PROFILE_VELOCITY: lambda: 0 <= new(ct.PROFILE_VELOCITY) <= 32767,
            ct.GOAL_POSITION: lambda: (
                new(ct.OPERATING_MODE) != ct.POSITION_MODE
                or 0 <= new(ct.GOAL_POSITION) < ct.POSITION_UNITS_PER_TURN
            ),
        }
        for item in touched:
            check = checks.get(item)
            if check is not None and not check():
                return DATA_LIMIT_ERROR if item in _GOALS else DATA_RANGE_ERROR
        return 0

    def _apply(self, staged: bytearray, touched: list[ct.Item]) -> None:
        was_on = self.torque_on
        old_mode = self.value(ct.OPERATING_MODE)
        self.table[:] = staged
        mode = self.value(ct.OPERATING_MODE)
        if ct.OPERATING_MODE in touched and mode == ct.POSITION_MODE != old_mode:
            self._rewrap()
        if ct.TORQUE_ENABLE in touched and self.torque_on and not was_on:
            if mode == ct.POSITION_MODE:
                self._rewrap()
            self._store(ct.GOAL_POSITION, round(self.position))
        self._refresh_present(self._velocity())

    def _rewrap(self) -> None:
        self.position = float(round(self.position) % ct.POSITION_UNITS_PER_TURN)

    def reboot(self) -> None:
        """Restarts the motor: torque off, errors and watchdog cleared, position re-wrapped."""
        for item in (ct.TORQUE_ENABLE, ct.HARDWARE_ERROR_STATUS, ct.BUS_WATCHDOG, ct.GOAL_VELOCITY):
            self._store(item, 0)
        self._rewrap()
        self._refresh_present(0.0)

    def snapshot(self) -> MotorSnapshot:
        """Returns the motor's state for inspection."""
        return MotorSnapshot(
            motor_id=self.motor_id,
            torque_enabled=self.torque_on,
            operating_mode=self.value(ct.OPERATING_MODE),
            goal_velocity=self.value(ct.GOAL_VELOCITY),
            present_velocity=self.value(ct.PRESENT_VELOCITY),
            position=self.value(ct.PRESENT_POSITION),
            temperature=self.value(ct.PRESENT_TEMPERATURE),
            hardware_error=self.hardware_error,
            bus_watchdog=self.value(ct.BUS_WATCHDOG),
            return_delay_time=self.value(ct.RETURN_DELAY_TIME),
        )
