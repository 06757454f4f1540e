"""The drives guard the host: the host produces a heartbeat, each drive consumes it and takes its
abort connection reaction when it stops (CiA 301 objects 0x1016 and 0x1017, CiA 402-2 object
0x6007).

A torque-off the host sends can be lost (the host killed, its last frames lost in a garbled
SLCAN line, the adapter unplugged); a drive that watches the host needs none of it. At connect
``CanArm`` starts ``HostHeartbeat`` (COB-ID 0x700 + ``master_id``, state byte 0x05, every
``master_heartbeat_ms``) and ``configure_drive_guard`` writes each drive's heartbeat consumer
0x1016 sub 1 (the host's node id and the consumer time) and its abort connection option code
0x6007, then reads both back. A drive that refuses either, or keeps another value, stops the
connect with one ``CanNodeError`` line naming the node and the object.

The heartbeat is a thread of the host's process: it runs while that process runs, whatever its
main thread does, and stops when the process dies, which is the point.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

from robot.canopen.network import CanNodeError, DriveNetwork

log = logging.getLogger(__name__)

HEARTBEAT_BASE = 0x700  # COB-ID of a node's heartbeat: 0x700 + node id (CiA 301)
NMT_OPERATIONAL = 0x05  # the state byte of a heartbeat from a node in OPERATIONAL (CiA 301)
CONSUMER_MAX_MS = 0xFFFF  # 0x1016's consumer time is the low 16 bits, ms (CiA 301)
# Where a user reads what a drive must support (said by every refusal).
GUARD_DOC = "docs/canopen.md, 'When the host dies'"


def consumer_entry(master_id: int, consumer_ms: int) -> int:
    """The value of 0x1016 sub 1: the producer's node id in bits 16-23, the time in ms in bits
    0-15 (0: consumer off)."""
    if not 1 <= master_id <= 127 or not 0 <= consumer_ms <= CONSUMER_MAX_MS:
        raise ValueError(f"heartbeat consumer: node {master_id}, {consumer_ms} ms out of range")
    return master_id << 16 | consumer_ms


def configure_drive_guard(
    net: DriveNetwork, i: int, master_id: int, consumer_ms: int, abort_option: int
) -> None:
    """Write node ``i``'s heartbeat consumer (0x1016 sub 1) of the host and its abort
    connection option code (0x6007), then read both back.

    Raises:
        CanNodeError: one line naming the node and the object the drive refused or changed.
    """
    entry = consumer_entry(master_id, consumer_ms)
    for index, sub, value, what in (
        (0x1016, 1, entry, f"heartbeat consumer (host node {master_id}, {consumer_ms} ms)"),
        (0x6007, 0, abort_option, "abort connection option code"),
    ):
        try:
            net.sdo_write(i, index, sub, value)
            back = net.sdo_read(i, index, sub)
        except CanNodeError as exc:
            raise CanNodeError(
                f"{exc}: its {what} is needed to stop the drive when the host dies ({GUARD_DOC})"
            ) from exc
        if back != value:
            raise CanNodeError(
                f"{net.who(i)} kept 0x{index:04X}:{sub} = {back} after the host wrote {value} "
                f"(its {what}; {GUARD_DOC})"
            )


class HostHeartbeat:
    """The host's heartbeat on ``network`` (a ``canopen.Network``), from a thread of its own.

    Args:
        network: the open network.
        master_id: the host's node id (COB-ID 0x700 + it).
        period_s: time between two heartbeats, s.
    """

    def __init__(self, network: Any, master_id: int, period_s: float) -> None:
        self.network = network
        self.cob_id = HEARTBEAT_BASE + master_id
        self.period_s = period_s
        self.sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="can-host-heartbeat", daemon=True)

    def start(self) -> HostHeartbeat:
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop sending (the drives' consumers then time out, as when the host dies)."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=1.0)

    def _run(self) -> None:
        failing = False
        while True:
            try:
                self.network.send_message(self.cob_id, bytes([NMT_OPERATIONAL]))
                self.sent += 1
                failing = False
            except Exception as exc:  # the link's failure is the cycle's to report
                if not failing:
                    log.debug("host heartbeat not sent: %s", exc)
                failing = True
            if self._stop.wait(self.period_s):
                return
