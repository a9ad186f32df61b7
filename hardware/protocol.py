"""Provides Dynamixel Protocol 2.0 framing: CRC-16, byte stuffing, packet build and parse.

The SDK frames the host side; this module frames the device side (the bus emulator) and
gives the tests an independent implementation to check the wire bytes against.
"""

from __future__ import annotations

from dataclasses import dataclass

HEADER = b"\xff\xff\xfd\x00"
BROADCAST_ID = 0xFE
MAX_ID = 252
STATUS_INSTRUCTION = 0x55

PING = 0x01
READ = 0x02
WRITE = 0x03
REBOOT = 0x08
SYNC_READ = 0x82
SYNC_WRITE = 0x83
BULK_READ = 0x92
BULK_WRITE = 0x93

MAX_LENGTH = 1024
"""Longest LEN field accepted; a larger one is junk and the reader resynchronises."""
_HEADER_AND_LENGTH = 7
"""FF FF FD 00, ID, LEN_L, LEN_H."""


def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else crc << 1
        table.append(crc & 0xFFFF)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc16(data: bytes) -> int:
    """Returns the CRC-16/UMTS (poly 0x8005, init 0, unreflected) of `data`."""
    crc = 0
    for byte in data:
        crc = ((crc << 8) ^ _CRC_TABLE[((crc >> 8) ^ byte) & 0xFF]) & 0xFFFF
    return crc


def stuff(body: bytes) -> bytes:
    """Returns `body` with an extra 0xFD after every FF FF FD (sender side)."""
    return body.replace(b"\xff\xff\xfd", b"\xff\xff\xfd\xfd")


def unstuff(body: bytes) -> bytes:
    """Returns `body` with the stuffed 0xFD after every FF FF FD removed (receiver side)."""
    return body.replace(b"\xff\xff\xfd\xfd", b"\xff\xff\xfd")


def build_packet(motor_id: int, instruction: int, params: bytes) -> bytes:
    """Returns a complete, stuffed Protocol 2.0 packet with its CRC.

    For a status packet pass `STATUS_INSTRUCTION` and the error byte as the first param.
    """
    body = stuff(bytes([instruction]) + params)
    length = len(body) + 2
    frame = HEADER + bytes([motor_id, length & 0xFF, length >> 8]) + body
    crc = crc16(frame)
    return frame + bytes([crc & 0xFF, crc >> 8])


def build_status(motor_id: int, error: int, params: bytes = b"") -> bytes:
    """Returns a status packet from `motor_id` with `error` and the returned data."""
    return build_packet(motor_id, STATUS_INSTRUCTION, bytes([error]) + params)


@dataclass(frozen=True)
class Packet:
    """One received, unstuffed packet."""

    motor_id: int
    instruction: int
    params: bytes


class PacketReader:
    """Splits a byte stream into packets; drops junk and packets with a bad CRC."""

    def __init__(self) -> None:
        self._buffer = bytearray()
        self.crc_failures = 0

    def feed(self, data: bytes) -> list[Packet]:
        """Returns the complete packets found after appending `data` to the buffer."""
        self._buffer.extend(data)
        packets = []
        while True:
            start = self._buffer.find(HEADER)
            if start < 0:
                # Keep a possible partial header at the end.
                del self._buffer[: max(0, len(self._buffer) - 3)]
                return packets
            del self._buffer[:start]
            if len(self._buffer) < _HEADER_AND_LENGTH:
                return packets
            length = self._buffer[5] | (self._buffer[6] << 8)
            if length > MAX_LENGTH:
                del self._buffer[:1]
                continue
            total = _HEADER_AND_LENGTH + length
            if len(self._buffer) < total:
                return packets
            frame = bytes(self._buffer[:total])
            del self._buffer[:total]
            if length < 3 or crc16(frame[:-2]) != (frame[-2] | (frame[-1] << 8)):
                self.crc_failures += 1
                continue
            body = unstuff(frame[_HEADER_AND_LENGTH:-2])
            packets.append(Packet(frame[4], body[0], body[1:]))
