"""``ergo bus scan``: list what answers on a Dynamixel serial bus or a CAN bus."""

from __future__ import annotations

import argparse
import importlib

# which flag -> "module:function(args) -> int"
SCANNERS: dict[str, str] = {
    "port": "robot.dynamixel.scan:scan_cli",
    "can": "robot.canopen.scan:scan_cli",
}


def register(sub: argparse._SubParsersAction) -> None:
    p_bus = sub.add_parser("bus", help="servo buses: scan")
    bus_sub = p_bus.add_subparsers(dest="bus_command", metavar="SUBCOMMAND")
    bus_sub.required = True
    scan = bus_sub.add_parser("scan", help="list servos (Dynamixel) or nodes (CANopen)")
    where = scan.add_mutually_exclusive_group(required=True)
    where.add_argument("--port", help="serial port of a Dynamixel bus, e.g. /dev/ttyUSB0")
    where.add_argument("--can", help="python-can bus, e.g. socketcan:can0, slcan:/dev/ttyACM0")
    scan.add_argument("--baud", type=int, default=1_000_000, help="serial baud rate")
    scan.add_argument("--bitrate", type=int, default=1_000_000, help="CAN bitrate")
    scan.add_argument("--ids", type=int, nargs="*", default=None, help="ids to probe (all)")
    scan.set_defaults(func=_scan)


def _scan(args: argparse.Namespace) -> int:
    key = "port" if args.port else "can"
    module_name, func_name = SCANNERS[key].split(":")
    module = importlib.import_module(module_name)
    return int(getattr(module, func_name)(args) or 0)
