"""Provides DxlBus: the one owner of a Dynamixel port, with typed errors and signed values."""

from __future__ import annotations

import select
import threading
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import TypeVar

import serial
from dynamixel_sdk import COMM_RX_TIMEOUT, COMM_SUCCESS, GroupSyncWrite, PacketHandler, PortHandler

from linkevo.hardware import control_table as ct
from linkevo.hardware.errors import (
    ALERT_BIT,
    CommError,
    DeviceError,
    MotorNotResponding,
    PortError,
    device_error_name,
)

_POLL_S = 0.001
T = TypeVar("T")


class _OwnedPort(PortHandler):
    """The SDK's PortHandler opened exclusively, with its own USB latency allowance.

    The SDK sizes every reply timeout from a module-level `LATENCY_TIMER` (16 ms); keeping
    the allowance per port avoids mutating that global.
    """

    def __init__(self, port_name: str, latency_ms: float) -> None:
        super().__init__(port_name)
        self.latency_ms = latency_ms

    def setPacketTimeout(self, packet_length: int) -> None:
        self.packet_start_time = self.getCurrentTime()
        self.packet_timeout = self.tx_time_per_byte * packet_length + 2.0 * self.latency_ms + 2.0

    def readPort(self, length: int) -> bytes:
        # The SDK polls in a tight loop; waiting up to 1 ms for input (returning as soon as
        # a byte arrives) frees the CPU and the GIL without adding latency.
        if not self.ser.in_waiting:
            select.select([self.ser.fileno()], [], [], _POLL_S)
        return self.ser.read(length)

    def setupPort(self, cflag_baud: int) -> bool:
        if self.is_open:
            self.closePort()
        self.ser = serial.Serial(
            port=self.port_name, baudrate=self.baudrate, timeout=0, exclusive=True
        )
        self.is_open = True
        self.ser.reset_input_buffer()
        self.tx_time_per_byte = (1000.0 / self.baudrate) * 10.0
        return True


@dataclass(frozen=True)
class Status:
    """One motor's answer to a sync read: decoded values and the alert flag."""

    values: Mapping[str, int]
    alert: bool


class DxlBus:
    """Protocol 2.0 bus on one serial port; the only object that talks to it.

    Use as a context manager. Every transaction takes the bus lock, so the SDK (not
    thread-safe) is never entered twice. Failures raise `CommError` (or its subclass
    `MotorNotResponding` for a timeout) and `DeviceError` for an error in a status packet.

    Args:
        port: serial device path (or the emulator's pty).
        baudrate: bits per second; one of the SDK's standard rates.
        latency_ms: USB adapter latency allowance per reply (FTDI default 16 ms).
        retries: extra attempts for ping, read, write, reboot and sync read on a comm
            failure.
    """

    def __init__(
        self, port: str, baudrate: int, *, latency_ms: float = 16.0, retries: int = 2
    ) -> None:
        self._port = _OwnedPort(port, latency_ms)
        self._packets = PacketHandler(2.0)
        self._baudrate = baudrate
        self._retries = retries
        self._lock = threading.RLock()

    @property
    def is_open(self) -> bool:
        return bool(self._port.is_open)

    def open(self) -> None:
        """Opens the port exclusively at the configured baud rate."""
        try:
            if not self._port.openPort() or not self._port.setBaudRate(self._baudrate):
                raise PortError(f"baud rate {self._baudrate} is not supported by the SDK")
        except serial.SerialException as exc:
            raise PortError(f"cannot open port {self._port.port_name!r}: {exc}") from exc

    def close(self) -> None:
        """Closes the port (idempotent)."""
        with self._lock:
            if self._port.is_open:
                self._port.closePort()

    def __enter__(self) -> DxlBus:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def release(self) -> None:
        """Frees the port after a transaction was interrupted (a signal or an exception).

        The SDK marks the port busy for the length of a transaction; an exception
        raised inside one leaves it marked, and every later call would fail as busy.
        """
        with self._lock:
            self._port.is_using = False
            if self._port.is_open:
                self._port.clearPort()

    def _check(self, motor_id: int, action: str, result: int, error: int) -> None:
        if result == COMM_RX_TIMEOUT:
            raise MotorNotResponding(
                f"motor {motor_id} did not answer ({action})", code=result, motor_id=motor_id
            )
        if result != COMM_SUCCESS:
            reason = self._packets.getTxRxResult(result)
            raise CommError(
                f"motor {motor_id}: {action} failed: {reason}", code=result, motor_id=motor_id
            )
        if error & ~ALERT_BIT:
            raise DeviceError(
                f"motor {motor_id}: {action} refused: {device_error_name(error)}",
                motor_id=motor_id,
                number=error & ~ALERT_BIT,
            )

    def _retrying(self, attempt: Callable[[], T], retries: int | None = None) -> T:
        """Returns attempt()'s value, running it again while it raises CommError, up to
        `retries` more times (None: the bus's). The SDK clears the port before each
        transmission, discarding what the failed attempt left there."""
        for _ in range(self._retries if retries is None else retries):
            try:
                return attempt()
            except CommError:
                pass
        return attempt()

    def _transact(self, motor_id: int, action: str, call: Callable[[], tuple[T, int, int]]) -> T:
        """Runs `call() -> (value, result, error)` with retries on comm failures."""

        def attempt() -> T:
            with self._lock:
                value, result, error = call()
            self._check(motor_id, action, result, error)
            return value

        return self._retrying(attempt)

    def ping(self, motor_id: int) -> int:
        """Returns the motor's model number."""
        return self._transact(motor_id, "ping", lambda: self._packets.ping(self._port, motor_id))

    def read(self, motor_id: int, item: ct.Item) -> int:
        """Returns the item's value (two's complement for signed items)."""

        def call() -> tuple[int, int, int]:
            data, result, error = self._packets.readTxRx(
                self._port, motor_id, item.address, item.size
            )
            value = ct.decode(item, bytes(data), item.address) if result == COMM_SUCCESS else 0
            return value, result, error

        return self._transact(motor_id, f"read {item.name}", call)

    def write(self, motor_id: int, item: ct.Item, value: int) -> None:
        """Writes the item (signed values are encoded in two's complement)."""
        data = list(ct.encode(item, value))

        def call() -> tuple[None, int, int]:
            result, error = self._packets.writeTxRx(
                self._port, motor_id, item.address, item.size, data
            )
            return None, result, error

        self._transact(motor_id, f"write {item.name}={value}", call)

    def reboot(self, motor_id: int) -> None:
        """Reboots the motor (clears a hardware error; torque comes back off)."""

        def call() -> tuple[None, int, int]:
            result, error = self._packets.reboot(self._port, motor_id)
            return None, result, error

        self._transact(motor_id, "reboot", call)

    def sync_write(self, item: ct.Item, values: Mapping[int, int]) -> None:
        """Writes one item to many motors in one broadcast packet (no reply)."""
        group = GroupSyncWrite(self._port, self._packets, item.address, item.size)
        for motor_id, value in values.items():
            group.addParam(motor_id, list(ct.encode(item, value)))
        with self._lock:
            result = group.txPacket()
        if result != COMM_SUCCESS:
            reason = self._packets.getTxRxResult(result)
            raise CommError(f"sync write of {item.name} failed: {reason}", code=result)

    def sync_read(
        self, items: tuple[ct.Item, ...], motor_ids: Iterable[int], *, retries: int | None = None
    ) -> dict[int, Status]:
        """Returns each motor's values of a contiguous run of items, from one SYNC_READ.

        Uses the SDK's packet handler directly (not GroupSyncRead) so that each status
        packet's error byte, and with it the hardware alert flag, is kept. A comm failure
        re-sends the whole SYNC_READ.

        Args:
            retries: extra attempts; None takes the bus's `retries`.

        Raises:
            MotorNotResponding: naming the first motor whose reply did not come.
        """
        ids = list(motor_ids)
        return self._retrying(lambda: self._sync_read_once(items, ids), retries)

    def _sync_read_once(self, items: tuple[ct.Item, ...], ids: list[int]) -> dict[int, Status]:
        start, length = ct.block_span(items)
        statuses = {}
        with self._lock:
            result = self._packets.syncReadTx(self._port, start, length, ids, len(ids), False)
            if result != COMM_SUCCESS:
                reason = self._packets.getTxRxResult(result)
                raise CommError(f"sync read failed: {reason}", code=result)
            for motor_id in ids:
                data, result, error = self._packets.readRx(self._port, motor_id, length)
                self._check(motor_id, "sync read", result, error)
                raw = bytes(data)
                values = {item.name: ct.decode(item, raw, start) for item in items}
                statuses[motor_id] = Status(values, bool(error & ALERT_BIT))
        return statuses
