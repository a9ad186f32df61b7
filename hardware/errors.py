"""Provides the typed errors of the hardware layer."""

from __future__ import annotations

from linkevo.sim.errors import LinkevoError

DEVICE_ERRORS = {
    1: "result fail",
    2: "instruction error",
    3: "CRC error",
    4: "data range error",
    5: "data length error",
    6: "data limit error",
    7: "access error",
}
"""Protocol 2.0 status-packet error numbers (the low 7 bits of the error byte)."""
ALERT_BIT = 0x80


class HardwareError(LinkevoError):
    """Base of every error the robot, its bus or its driver raises (`hardware/`)."""


class PortError(HardwareError):
    """The serial port cannot be opened or set up."""


class CommError(HardwareError):
    """A transaction failed on the wire (SDK result code other than success)."""

    def __init__(self, message: str, *, code: int, motor_id: int | None = None) -> None:
        super().__init__(message)
        self.code = code
        self.motor_id = motor_id


class MotorNotResponding(CommError):
    """A motor did not answer (timeout): it is missing, unpowered or on another baud rate."""


class DeviceError(HardwareError):
    """A motor answered with an error number in its status packet."""

    def __init__(self, message: str, *, motor_id: int, number: int) -> None:
        super().__init__(message)
        self.motor_id = motor_id
        self.number = number


class WrongModel(HardwareError):
    """A motor answered the ping with a model number other than the MX-28(2.0)."""


class SafetyStop(HardwareError):
    """The safety monitor stopped the walk (limit exceeded or hardware error)."""

    def __init__(self, message: str, *, motor_id: int) -> None:
        super().__init__(message)
        self.motor_id = motor_id


class AlignmentError(HardwareError):
    """The legs did not reach their phase offsets in position mode in time."""


class ShutdownIncomplete(HardwareError):
    """The shutdown could not stop every motor or turn its torque off; the message names
    what failed. Raised from the error that ended the walk, if one did."""


class StopRequested(HardwareError):
    """A SIGINT or SIGTERM asked the walk to stop; the motors were stopped safely."""

    def __init__(self, signal_name: str) -> None:
        super().__init__(f"stopped by {signal_name}")
        self.signal_name = signal_name


def device_error_name(error_byte: int) -> str:
    """Returns the meaning of a status packet's error number."""
    number = error_byte & ~ALERT_BIT
    return DEVICE_ERRORS.get(number, f"unknown error {number}")
