"""Typed errors of the hardware layer. Each message is one line naming what went wrong."""


class RobotError(RuntimeError):
    """Base class of every hardware-layer error."""


class NotConnectedError(RobotError):
    """An operation needed a connected arm."""


class BusError(RobotError):
    """The bus (serial port, CAN adapter) failed: unplugged, busy, wrong settings."""


class SafetyStop(RobotError):
    """The arm was stopped for safety (overload, overheat, lost node); torque is off."""


class LinkLost(BusError):
    """The link to the servos itself failed (adapter unplugged, serial port or CAN interface
    gone), as opposed to a packet lost on a working link. ``Arm`` reacts by reconnecting."""
