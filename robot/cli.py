"""``ergo bus scan``: list what answers on a Dynamixel serial bus or a CAN bus; ``ergo bus
set-id``: give a Dynamixel servo its id."""

from __future__ import annotations

import argparse

from plumbing.registry import LazyTable
from robot.bus_flags import add_bus_arguments, bus_from_args

# bus kind -> "module:function(args) -> int"
SCANNERS = LazyTable(
    "bus scanner",
    {"dynamixel": "robot.dynamixel.scan:scan_cli", "canopen": "robot.canopen.scan:scan_cli"},
)


def register(sub: argparse._SubParsersAction) -> None:
    p_bus = sub.add_parser("bus", help="servo buses: scan, set a servo's id")
    bus_sub = p_bus.add_subparsers(dest="bus_command", metavar="SUBCOMMAND")
    bus_sub.required = True
    scan = bus_sub.add_parser("scan", help="list servos (Dynamixel) or nodes (CANopen)")
    add_bus_arguments(scan, required=True)
    scan.add_argument("--ids", type=int, nargs="*", default=None, help="ids to probe (all)")
    scan.set_defaults(func=_scan)
    set_id = bus_sub.add_parser(
        "set-id", help="give the one Dynamixel servo on the bus its id (factory XL-320s are 1)"
    )
    set_id.add_argument("--port", required=True, help="serial port, e.g. /dev/ttyUSB0")
    set_id.add_argument("--baud", type=int, default=None, help="bit/s (default 1000000)")
    set_id.add_argument("--id", type=int, default=1, help="the servo's id now (default 1)")
    set_id.add_argument("--new-id", type=int, required=True, help="the id to give it")
    set_id.set_defaults(func=_set_id)


def _set_id(args: argparse.Namespace) -> int:
    from robot.dynamixel.ids import set_id_cli

    return set_id_cli(args)


def _scan(args: argparse.Namespace) -> int:
    bus = bus_from_args(args)
    assert bus is not None  # argparse requires --port or --can
    return int(SCANNERS.load(bus.kind)(args) or 0)
