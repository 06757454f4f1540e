"""The bus flags, declared once for every command that talks to an arm (``ergo explore``,
``ergo experiment``, ``ergo calibrate joints``, ``ergo bus scan``): ``--port``/``--baud`` for a
Dynamixel serial bus, ``--can``/``--bitrate`` for a CANopen bus; and the arm they name.

Imports nothing heavy: the backends (pyserial, python-can) are loaded when an arm is made.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import Any, Literal

from plumbing.registry import LazyTable
from robot.canopen.bus import DEFAULT_BITRATE
from robot.dynamixel.bus import DEFAULT_BAUD

# bus kind -> the arm class on that bus: ``cls(where, rate, **kw)``
ARMS = LazyTable(
    "arm backend",
    {"dynamixel": "robot.dynamixel.arm:DynamixelArm", "canopen": "robot.canopen.arm:CanArm"},
)

PORT_HELP = "Dynamixel bus: serial port, e.g. /dev/ttyUSB0 or the pty of `ergo twin serve`"
CAN_HELP = "CANopen bus: python-can INTERFACE:CHANNEL, e.g. socketcan:can0, slcan:/dev/ttyACM0"


@dataclass(frozen=True)
class Bus:
    """A bus named by the flags.

    Attributes:
        kind: "dynamixel" (``--port``) or "canopen" (``--can``).
        where: the serial port, or the python-can ``INTERFACE:CHANNEL``.
        rate: baud rate or CAN bitrate, bit/s (the default when not given).
    """

    kind: Literal["dynamixel", "canopen"]
    where: str
    rate: int


def add_bus_arguments(
    parser: argparse.ArgumentParser, *, required: bool = False, exclusive: bool = True
) -> None:
    """``--port``/``--can`` (one of them, ``required`` or not; ``exclusive=False`` lets a
    command take both and pick by another flag, as ``--rig``) and ``--baud``/``--bitrate``."""
    where: Any = parser.add_mutually_exclusive_group(required=required) if exclusive else parser
    where.add_argument("--port", help=PORT_HELP)
    where.add_argument("--can", help=CAN_HELP)
    parser.add_argument(
        "--baud", type=int, default=None, help=f"with --port: baud rate (default {DEFAULT_BAUD})"
    )
    parser.add_argument(
        "--bitrate", type=int, default=None,
        help=f"with --can: CAN bitrate (default {DEFAULT_BITRATE})",
    )  # fmt: skip


def bus_flags(args: argparse.Namespace) -> dict[str, Any]:
    """The bus flags given (port, baud, can, bitrate), by name; the ones not given left out."""
    return {
        key: getattr(args, key)
        for key in ("port", "baud", "can", "bitrate")
        if getattr(args, key, None) is not None
    }


def bus_from_args(args: argparse.Namespace) -> Bus | None:
    """The bus ``--port`` or ``--can`` names (``--port`` first), with its rate; None if neither."""
    if getattr(args, "port", None):
        return Bus("dynamixel", args.port, getattr(args, "baud", None) or DEFAULT_BAUD)
    if getattr(args, "can", None):
        return Bus("canopen", args.can, getattr(args, "bitrate", None) or DEFAULT_BITRATE)
    return None


def make_arm(bus: Bus, **kw: Any) -> Any:
    """The (unconnected) ``robot.Arm`` on ``bus``: ``DynamixelArm(port, baud, **kw)`` or
    ``CanArm(can, bitrate, **kw)`` with their defaults (directions +1, offsets 0; a CanArm
    on the emulator's pty with ``robot.canopen.arm.config_for``'s pty settings)."""
    if bus.kind == "canopen" and "config" not in kw:
        from robot.canopen.arm import config_for

        kw = {**kw, "config": config_for(bus.where)}
    return ARMS.load(bus.kind)(bus.where, bus.rate, **kw)
