"""``ergo bus scan``: list what answers on a Dynamixel serial bus or a CAN bus."""

from __future__ import annotations

import argparse

from robot.bus_flags import add_bus_arguments, bus_from_args
from robot.registry import LazyTable

# bus kind -> "module:function(args) -> int"
SCANNERS = LazyTable(
    "bus scanner",
    {"dynamixel": "robot.dynamixel.scan:scan_cli", "canopen": "robot.canopen.scan:scan_cli"},
)


def register(sub: argparse._SubParsersAction) -> None:
    p_bus = sub.add_parser("bus", help="servo buses: scan")
    bus_sub = p_bus.add_subparsers(dest="bus_command", metavar="SUBCOMMAND")
    bus_sub.required = True
    scan = bus_sub.add_parser("scan", help="list servos (Dynamixel) or nodes (CANopen)")
    add_bus_arguments(scan, required=True)
    scan.add_argument("--ids", type=int, nargs="*", default=None, help="ids to probe (all)")
    scan.set_defaults(func=_scan)


def _scan(args: argparse.Namespace) -> int:
    bus = bus_from_args(args)
    assert bus is not None  # argparse requires --port or --can
    return int(SCANNERS.load(bus.kind)(args) or 0)
