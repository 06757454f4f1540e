"""The typed errors of the Dynamixel bus (``robot/dynamixel/bus.py``): what a call raises when
a servo does not answer, answers garbled, reports an error or an alert, or the port goes."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from robot.dynamixel import protocol as proto
from robot.errors import BusError, LinkLost


class DynamixelError(BusError):
    """Base of the Dynamixel bus errors."""


class PortLostError(DynamixelError, LinkLost):
    """The serial port failed under the bus (adapter unplugged, pty closed): a ``LinkLost``,
    which the arm answers by reopening the port by name."""


class CallPreemptedError(DynamixelError):
    """A call gave up because another thread took the bus for an emergency torque off."""


class NoStatusError(DynamixelError):
    """No status packet arrived in time (servo absent, unpowered, wrong id or baud rate).

    Attributes:
        ids: the servos that did not answer.
    """

    def __init__(self, message: str, ids: Sequence[int] = ()) -> None:
        super().__init__(message)
        self.ids = list(ids)


class CorruptPacketError(DynamixelError):
    """Status packets arrived but failed their CRC (noise, wrong baud rate, collision)."""

    def __init__(self, message: str, ids: Sequence[int] = ()) -> None:
        super().__init__(message)
        self.ids = list(ids)


class ServoError(DynamixelError):
    """A servo answered with an error in its status packet.

    Attributes:
        servo_id: who answered.
        error: the decoded error byte.
    """

    def __init__(self, message: str, servo_id: int, error: proto.StatusError) -> None:
        super().__init__(message)
        self.servo_id = servo_id
        self.error = error


class HardwareAlertError(ServoError):
    """A servo raised its alert bit; its Hardware Error Status was read and decoded.

    Attributes:
        hardware_status: the raw Hardware Error Status byte (-1 if it could not be read).
        bits: names of the bits set (e.g. ["overload"]).
        data: what the call had read before the alert (id -> bytes), for callers that want it.
    """

    def __init__(
        self,
        message: str,
        servo_id: int,
        error: proto.StatusError,
        hardware_status: int,
        bits: list[str],
        data: Mapping[int, bytes] | None = None,
    ) -> None:
        super().__init__(message, servo_id, error)
        self.hardware_status = hardware_status
        self.bits = bits
        self.data = dict(data or {})
