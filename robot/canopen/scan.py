"""``ergo bus scan --can SPEC``: list the CANopen nodes on a bus.

Every node that answers an SDO request (or sends a heartbeat, EMCY or PDO) during the listening
window is listed with its device type 0x1000, identity 0x1018 (vendor, product, revision,
serial) and the NMT state from its last heartbeat. Uses the ``canopen`` library's node scanner
and SDO client; sends nothing but SDO reads.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass

from plumbing.cli_errors import error
from robot.canopen.bus import (
    DEFAULT_BITRATE,
    CanBusError,
    garbled_words,
    open_bus,
    parse_can_spec,
)

# How long to listen for answers and heartbeats, s (guess: covers heartbeat times up to 1 s,
# and the SDO answers of 127 nodes at any bitrate >= 125 kbit/s).
LISTEN_S = 1.2
# SDO timeout per read while scanning, s (canopen's default is 0.3 s).
SDO_TIMEOUT_S = 0.3
# Device profile numbers (CiA 301 0x1000 low word).
PROFILES = {401: "CiA 401 I/O", 402: "CiA 402 drive", 406: "CiA 406 encoder"}


@dataclass
class NodeInfo:
    """What a scan learned about one node (None: not readable)."""

    node_id: int
    device_type: int | None = None
    vendor: int | None = None
    product: int | None = None
    revision: int | None = None
    serial: int | None = None
    nmt_state: str | None = None
    error: str | None = None

    @property
    def profile(self) -> str:
        if self.device_type is None:
            return "?"
        number = self.device_type & 0xFFFF
        return PROFILES.get(number, f"CiA {number}")


@dataclass
class ScanResult:
    """The nodes found (by id) and the lines an SLCAN adapter sent that were dropped as
    garbage meanwhile (0 on other adapters)."""

    nodes: list[NodeInfo]
    garbled_lines: int = 0


def _hex(value: int | None) -> str:
    return "?" if value is None else f"0x{value:08X}"


def scan(
    spec: str,
    bitrate: int | None = DEFAULT_BITRATE,
    ids: Sequence[int] | None = None,
    listen_s: float = LISTEN_S,
) -> ScanResult:
    """Find the nodes among ``ids`` (default 1..127) on the bus ``spec``.

    Raises:
        CanBusError: bad spec or the adapter could not be opened.
    """
    import canopen
    from canopen.nmt import NMT_STATES
    from canopen.sdo import SdoAbortedError, SdoClient, SdoCommunicationError

    wanted = sorted(set(ids)) if ids else list(range(1, 128))
    bad = [i for i in wanted if not 1 <= i <= 127]
    if bad:
        raise CanBusError(f"CANopen node ids are 1..127, got {bad}")
    bus = open_bus(parse_can_spec(spec, bitrate))
    network = canopen.Network(bus)
    heard: dict[int, int] = {}
    lock = threading.Lock()

    def on_heartbeat(can_id: int, data: bytearray, _ts: float) -> None:
        if data:
            with lock:
                heard[can_id - 0x700] = data[0] & 0x7F

    try:
        network.connect()
        for nid in wanted:
            network.subscribe(0x700 + nid, on_heartbeat)
        network.scanner.search(limit=max(wanted))
        time.sleep(listen_s)
        found = sorted(set(network.scanner.nodes) & set(wanted))
        infos = []
        for nid in found:
            info = NodeInfo(nid)
            sdo = SdoClient(0x600 + nid, 0x580 + nid, canopen.ObjectDictionary())
            sdo.RESPONSE_TIMEOUT = SDO_TIMEOUT_S
            sdo.network = network
            network.subscribe(0x580 + nid, sdo.on_response)
            try:
                info.device_type = int.from_bytes(sdo.upload(0x1000, 0)[:4], "little")
                fields = ("vendor", "product", "revision", "serial")
                for sub, name in enumerate(fields, start=1):
                    raw = sdo.upload(0x1018, sub)
                    setattr(info, name, int.from_bytes(raw[:4], "little"))
            except (SdoCommunicationError, SdoAbortedError) as exc:
                info.error = " ".join(str(exc).split())
            finally:
                network.unsubscribe(0x580 + nid, sdo.on_response)
            with lock:
                state = heard.get(nid)
            if state is not None:
                info.nmt_state = "BOOT-UP" if state == 0 else NMT_STATES.get(state, str(state))
            infos.append(info)
        return ScanResult(infos, int(getattr(bus, "garbled_lines", 0)))
    finally:
        network.disconnect()


def format_table(infos: Sequence[NodeInfo]) -> str:
    """A fixed-width table, one node per line."""
    head = (
        f"{'node':>4}  {'device type':<11}  {'profile':<15}  {'vendor':<10}  {'product':<10}  "
        f"{'revision':<10}  {'serial':<10}  NMT state"
    )
    rows = [head]
    for n in infos:
        state = n.nmt_state or "no heartbeat"
        row = (
            f"{n.node_id:>4}  {_hex(n.device_type):<11}  {n.profile:<15}  {_hex(n.vendor):<10}  "
            f"{_hex(n.product):<10}  {_hex(n.revision):<10}  {_hex(n.serial):<10}  {state}"
        )
        if n.error:
            row += f"  ({n.error})"
        rows.append(row)
    return "\n".join(rows)


def scan_cli(args: argparse.Namespace) -> int:
    """``ergo bus scan --can SPEC [--bitrate B] [--ids ...]``: print the table; exit 0 if a
    node answered, 1 if none, 2 on a bus error."""
    ids = getattr(args, "ids", None) or None
    try:
        result = scan(
            args.can,
            getattr(args, "bitrate", None) or DEFAULT_BITRATE,
            ids,
            float(getattr(args, "listen_s", LISTEN_S)),
        )
    except CanBusError as exc:
        return error(exc)
    note = garbled_words(result.garbled_lines)
    if not result.nodes:
        which = "ids " + " ".join(map(str, ids)) if ids else "ids 1..127"
        print(f"no CANopen node answered on {args.can} ({which}){note}", file=sys.stderr)
        return 1
    print(format_table(result.nodes))
    if note:
        print(f"ergo: warning: {note[2:]}", file=sys.stderr)
    return 0
