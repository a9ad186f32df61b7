"""Provides BusEmulator: several MX-28(2.0) motors answering Protocol 2.0 on a pseudo-terminal.

The real `dynamixel_sdk` opens the pty's slave path like a USB adapter; a thread reads
the master side, parses packets (CRC, byte stuffing), updates the emulated motors and
writes status packets back. Fault injection covers dropped replies, bad CRCs, heating,
hardware errors, extra load and supply voltage.
"""

from __future__ import annotations

import collections
import contextlib
import os
import pty
import select
import threading
import time
import tty
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from linkevo.hardware import control_table as ct
from linkevo.hardware import protocol as p
from linkevo.hardware.emulated_motor import EmulatedMotor, MotorSnapshot

INSTRUCTION_ERROR = 2
_LOG_LIMIT = 200_000


@dataclass(frozen=True)
class LoggedPacket:
    """One instruction packet the emulator received (after CRC check and unstuffing)."""

    time: float
    motor_id: int
    instruction: int
    params: bytes


@dataclass(frozen=True)
class LoggedWrite:
    """One register write a motor received, from WRITE or SYNC_WRITE."""

    time: float
    motor_id: int
    address: int
    data: bytes
    instruction: int

    @property
    def value(self) -> int:
        """Returns the written bytes as a signed little-endian integer."""
        return int.from_bytes(self.data, "little", signed=True)


class BusEmulator:
    """Stateful multi-motor Protocol 2.0 bus on a pty; use as a context manager.

    Args:
        motor_ids: the ids present on the bus.
        velocity_limit: Velocity Limit (address 44) each motor starts with.
        model_number: what the motors answer to a ping (30 = MX-28(2.0)).
        clock: seconds, monotonic; motion is integrated against it.
        motor_factory: makes each motor (`motor_factory(id, now=..., velocity_limit=...,
            model_number=...)`); default `EmulatedMotor`, whose shaft turns as commanded
            (`hardware.physics_bus.PhysicsWorld.motor_factory`: the simulated robot's cranks).
    """

    def __init__(
        self,
        motor_ids: Iterable[int],
        *,
        velocity_limit: int = 230,
        model_number: int = ct.MX28_MODEL_NUMBER,
        clock: Callable[[], float] = time.monotonic,
        motor_factory: Callable[..., EmulatedMotor] = EmulatedMotor,
    ) -> None:
        self._clock = clock
        now = clock()
        self._motors = {
            i: motor_factory(i, now=now, velocity_limit=velocity_limit, model_number=model_number)
            for i in sorted(motor_ids)
        }
        self._lock = threading.Lock()
        self._drop: dict[int, int] = {}
        self._corrupt: dict[int, int] = {}
        self._log: collections.deque[LoggedPacket] = collections.deque(maxlen=_LOG_LIMIT)
        self._reader = p.PacketReader()
        self._master, self._slave = pty.openpty()
        tty.setraw(self._slave)
        self.port = os.ttyname(self._slave)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="dxl-emulator", daemon=True)

    def start(self) -> BusEmulator:
        """Starts answering on the pty; returns self."""
        self._thread.start()
        return self

    def close(self) -> None:
        """Stops the serving thread and closes the pty."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        for fd in (self._master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)

    def __enter__(self) -> BusEmulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- inspection -------------------------------------------------------------------

    def snapshot(self, motor_id: int) -> MotorSnapshot:
        """Returns one motor's state, advanced to now."""
        with self._lock:
            motor = self._motors[motor_id]
            motor.advance(self._clock())
            return motor.snapshot()

    def snapshots(self) -> dict[int, MotorSnapshot]:
        """Returns every motor's state, advanced to now, keyed by id."""
        return {i: self.snapshot(i) for i in self._motors}

    def packets(self) -> list[LoggedPacket]:
        """Returns the instruction packets received so far, oldest first."""
        with self._lock:
            return list(self._log)

    def writes(self) -> list[LoggedWrite]:
        """Returns every register write (WRITE and SYNC_WRITE), oldest first."""
        writes = []
        for packet in self.packets():
            params = packet.params
            if packet.instruction == p.WRITE:
                address = int.from_bytes(params[:2], "little")
                writes.append(
                    LoggedWrite(packet.time, packet.motor_id, address, params[2:], p.WRITE)
                )
            elif packet.instruction == p.SYNC_WRITE:
                address = int.from_bytes(params[:2], "little")
                size = int.from_bytes(params[2:4], "little")
                for at in range(4, len(params), size + 1):
                    data = params[at + 1 : at + 1 + size]
                    writes.append(LoggedWrite(packet.time, params[at], address, data, p.SYNC_WRITE))
        return writes

    @property
    def crc_failures(self) -> int:
        """Returns how many received packets were dropped for a bad CRC."""
        return self._reader.crc_failures

    # --- fault injection --------------------------------------------------------------

    def drop_replies(self, motor_id: int, count: int = 1) -> None:
        """Makes the motor stay silent for its next `count` replies."""
        with self._lock:
            self._drop[motor_id] = count

    def corrupt_replies(self, motor_id: int, count: int = 1) -> None:
        """Sends the motor's next `count` replies with a wrong CRC."""
        with self._lock:
            self._corrupt[motor_id] = count

    def heat(self, motor_id: int, c_per_s: float) -> None:
        """Makes the motor's temperature rise at `c_per_s` °C per second from now."""
        with self._lock:
            motor = self._motors[motor_id]
            motor.advance(self._clock())
            motor.heating_c_per_s = c_per_s

    def set_hardware_error(self, motor_id: int, bits: int) -> None:
        """Raises Hardware Error Status bits (torque drops for bits in the Shutdown mask)."""
        with self._lock:
            motor = self._motors[motor_id]
            motor.advance(self._clock())
            motor.set_hardware_error(bits)

    # --- serving ----------------------------------------------------------------------

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self._master], [], [], 0.05)
                if not ready:
                    continue
                data = os.read(self._master, 4096)
            except OSError:
                return
            reply = bytearray()
            for packet in self._reader.feed(data):
                with self._lock:
                    reply += self._handle(packet)
            if reply:
                try:
                    os.write(self._master, bytes(reply))
                except OSError:
                    return

    def _handle(self, packet: p.Packet) -> bytes:
        now = self._clock()
        self._log.append(LoggedPacket(now, packet.motor_id, packet.instruction, packet.params))
        for motor in self._motors.values():
            motor.advance(now)
            motor.last_packet = now
        handler = {
            p.PING: self._ping,
            p.READ: self._read,
            p.WRITE: self._write,
            p.REBOOT: self._reboot,
            p.SYNC_READ: self._sync_read,
            p.SYNC_WRITE: self._sync_write,
            p.BULK_READ: self._bulk_read,
            p.BULK_WRITE: self._bulk_write,
        }.get(packet.instruction)
        if handler is None:
            return self._status(packet.motor_id, INSTRUCTION_ERROR, level=2)
        return handler(packet.motor_id, packet.params)

    def _status(self, motor_id: int, error: int, data: bytes = b"", *, level: int) -> bytes:
        """Returns the status packet for `motor_id`, or b"" when it must stay silent.

        `level` is the lowest Status Return Level (address 68) that still answers.
        """
        motor = self._motors.get(motor_id)
        if motor is None or motor.value(ct.STATUS_RETURN_LEVEL) < level:
            return b""
        if self._drop.get(motor_id, 0) > 0:
            self._drop[motor_id] -= 1
            return b""
        if motor.hardware_error:
            error |= 0x80
        packet = p.build_status(motor_id, error, data)
        if self._corrupt.get(motor_id, 0) > 0:
            self._corrupt[motor_id] -= 1
            packet = packet[:-1] + bytes([packet[-1] ^ 0xFF])
        return packet

    def _targets(self, motor_id: int) -> list[int]:
        return list(self._motors) if motor_id == p.BROADCAST_ID else [motor_id]

    def _ping(self, motor_id: int, params: bytes) -> bytes:
        reply = b""
        for target in self._targets(motor_id):
            motor = self._motors.get(target)
            if motor is not None:
                info = motor.table[0:2] + motor.table[6:7]
                reply += self._status(target, 0, bytes(info), level=0)
        return reply

    def _read(self, motor_id: int, params: bytes) -> bytes:
        motor = self._motors.get(motor_id)
        if motor is None or len(params) != 4:
            return b""
        address = int.from_bytes(params[:2], "little")
        length = int.from_bytes(params[2:4], "little")
        error, data = motor.read(address, length)
        return self._status(motor_id, error, data, level=1)

    def _write(self, motor_id: int, params: bytes) -> bytes:
        address = int.from_bytes(params[:2], "little")
        reply = b""
        for target in self._targets(motor_id):
            motor = self._motors.get(target)
            if motor is not None:
                error = motor.write(address, params[2:])
                if motor_id != p.BROADCAST_ID:
                    reply += self._status(target, error, level=2)
        return reply

    def _reboot(self, motor_id: int, params: bytes) -> bytes:
        reply = b""
        for target in self._targets(motor_id):
            motor = self._motors.get(target)
            if motor is not None:
                if motor_id != p.BROADCAST_ID:
                    reply += self._status(target, 0, level=2)
                motor.reboot()
        return reply

    def _sync_read(self, motor_id: int, params: bytes) -> bytes:
        address = int.from_bytes(params[:2], "little")
        length = int.from_bytes(params[2:4], "little")
        reply = b""
        for target in params[4:]:
            motor = self._motors.get(target)
            if motor is not None:
                error, data = motor.read(address, length)
                reply += self._status(target, error, data, level=1)
        return reply

    def _sync_write(self, motor_id: int, params: bytes) -> bytes:
        address = int.from_bytes(params[:2], "little")
        size = int.from_bytes(params[2:4], "little")
        for at in range(4, len(params), size + 1):
            motor = self._motors.get(params[at])
            if motor is not None:
                motor.write(address, params[at + 1 : at + 1 + size])
        return b""

    def _bulk_read(self, motor_id: int, params: bytes) -> bytes:
        reply = b""
        for at in range(0, len(params), 5):
            target = params[at]
            motor = self._motors.get(target)
            if motor is not None:
                address = int.from_bytes(params[at + 1 : at + 3], "little")
                length = int.from_bytes(params[at + 3 : at + 5], "little")
                error, data = motor.read(address, length)
                reply += self._status(target, error, data, level=1)
        return reply

    def _bulk_write(self, motor_id: int, params: bytes) -> bytes:
        at = 0
        while at + 5 <= len(params):
            target = params[at]
            address = int.from_bytes(params[at + 1 : at + 3], "little")
            length = int.from_bytes(params[at + 3 : at + 5], "little")
            motor = self._motors.get(target)
            if motor is not None:
                motor.write(address, params[at + 5 : at + 5 + length])
            at += 5 + length
        return b""
