"""The emulated drives' heartbeat consumer of the host: what a CiA 402 drive does when the host
that commands it goes silent (the host's side: ``robot.canopen.guard``).

Each drive consumes the heartbeat of the node its 0x1016 sub 1 names (bits 16-23; the consumer
time in ms in bits 0-15, 0: off). As CiA 301 says, the watch starts with the first heartbeat
heard after it was configured. When that node is silent for longer than the consumer time, the
drive sends EMCY 0x8130 (life guard or heartbeat error; error register: generic and
communication) and takes the reaction its abort connection option code 0x6007 names (CiA
402-2):

- 0 no action (the drive keeps following its last target);
- 1 fault: FAULT (torque off), cleared by a fault reset;
- 2 disable voltage: SWITCH ON DISABLED, torque off;
- 3 quick stop: the quick stop command (from OPERATION ENABLED to QUICK STOP ACTIVE,
  transition 11; from the other powered states to SWITCH ON DISABLED); the emulated drive
  stops at once (no deceleration ramp, 0x6085), then stays in QUICK STOP ACTIVE holding its
  position, or goes on to SWITCH ON DISABLED, as its quick stop option code 0x605A says
  (``sim.canopen.drive``).

The watch then rests until the node is heard again, which also clears the error (EMCY 0x0000)
unless the drive is in FAULT.

Unlike a drive's firmware, the emulator shares a machine with the host and can itself be
starved of CPU for a while, with the host's heartbeats waiting unread meanwhile. So time does
not count as silence while frames wait unread (``backlog``: bytes in the pty from the host, or
frames in the drives' own bus queue), and a stall of the watch's own thread longer than
``STALL_S`` counts only as ``STALL_S``: the host's heartbeat is not called missing because
the emulator did not run.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any, Protocol

from canopen.sdo import SdoAbortedError

from robot.canopen.cia402 import CW_DISABLE_VOLTAGE, CW_QUICK_STOP, State


class EmulatedDrive(Protocol):
    """What the watch needs of an emulated drive (``sim.canopen.drive.EmulatedDrive``; a
    protocol, so that this module does not import the drives that import it)."""

    node_id: int
    state: State
    error_code: int
    node: Any  # its canopen LocalNode (``node.emcy``)

    def od_int(self, index: int, subindex: int = 0) -> int: ...

    def trip(self, code: int = ..., register: int = ...) -> None: ...

    def apply_controlword(self, cw: int) -> None: ...


log = logging.getLogger(__name__)

HEARTBEAT_CONSUMER_ERROR = 0x8130  # EMCY: life guard or heartbeat error (CiA 301)
# Error register with it: generic (bit 0) and communication (bit 4) (CiA 301 0x1001).
COMMUNICATION_REGISTER = 0x11
ABORT_OPTIONS = (0, 1, 2, 3)  # 0x6007 values the emulated drive implements (CiA 402-2)
ABORT_VALUE_RANGE = 0x06090030  # SDO abort code: value range of parameter exceeded (CiA 301)
# How often the watch looks, s (guess: a hundredth of the shortest consumer time the host
# writes, 1 s, so the reaction comes at most this late).
CHECK_PERIOD_S = 0.01
# The longest gap of the watch's own thread that counts in full as the host's silence, s
# (guess: a quarter of the emulator's consumer time, 2 s; a longer gap is the emulator
# starved, not the host silent).
STALL_S = 0.5
# States in which the reactions 2 and 3 apply (CiA 402-2: disable voltage, transitions 7, 9,
# 10, 12; quick stop, transitions 7, 10, 11).
POWERED = (
    State.READY_TO_SWITCH_ON,
    State.SWITCHED_ON,
    State.OPERATION_ENABLED,
    State.QUICK_STOP_ACTIVE,
)


def check_guard_write(index: int, data: bytes) -> None:
    """Refuse (SDO abort "value range") an abort connection option the drive does not
    implement; any consumer entry 0x1016 is taken."""
    if index == 0x6007 and int.from_bytes(data[:2], "little", signed=True) not in ABORT_OPTIONS:
        raise SdoAbortedError(ABORT_VALUE_RANGE)


class HostGuard:
    """The heartbeat consumer of every drive of ``drives``, run by a thread of its own.

    Args:
        drives: the emulated drives.
        lock: the drives' lock (their state is changed under it).
        backlog: whether frames from the host wait unread now (time then is not silence).
    """

    def __init__(
        self, drives: Sequence[EmulatedDrive], lock: Any, backlog: Callable[[], bool]
    ) -> None:
        self.drives = list(drives)
        self.lock = lock
        self.backlog = backlog
        self.heard_at: dict[int, float] = {}  # producer node id -> monotonic s
        self._silent = {d.node_id: 0.0 for d in self.drives}  # s of silence counted
        self._watching = {d.node_id: False for d in self.drives}
        self._entry = {d.node_id: 0 for d in self.drives}  # the 0x1016:1 being watched
        self.reactions: list[tuple[int, float]] = []  # (node id, monotonic s) of each reaction
        #: the longest silence of a watched host that ended with its heartbeat, s (the host was
        #: alive: what a consumer time must stay above; ``ergo twin serve`` logs it at the end)
        self.longest_silence_s = 0.0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def subscriptions(self) -> list[tuple[int, Callable[[int, bytearray, float], None]]]:
        """(COB-ID, callback) of every heartbeat a drive may consume: those of the nodes that
        are not the drives themselves."""
        own = {d.node_id for d in self.drives}
        return [(0x700 + n, self.on_heartbeat) for n in range(1, 128) if n not in own]

    def on_heartbeat(self, can_id: int, data: bytearray, timestamp: float) -> None:
        """A heartbeat from node ``can_id - 0x700`` (the notifier thread)."""
        self.heard_at[can_id - 0x700] = time.monotonic()

    def start(self) -> None:
        """Start watching (a thread of its own, ``CHECK_PERIOD_S``)."""
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="drives-host-guard", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop watching (no reaction after it returns)."""
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(timeout=2.0)

    def _run(self) -> None:
        last = time.monotonic()
        seen: dict[int, float] = {}
        while not self._stop.wait(CHECK_PERIOD_S):
            now = time.monotonic()
            step, last = (0.0 if self.backlog() else min(now - last, STALL_S)), now
            for d in self.drives:
                self._check(d, step, seen)

    def _check(self, d: EmulatedDrive, step: float, seen: dict[int, float]) -> None:
        entry = d.od_int(0x1016, 1)
        producer, consumer_s = entry >> 16 & 0x7F, (entry & 0xFFFF) / 1000
        n = d.node_id
        if entry != self._entry[n]:  # (re)configured: wait for the first heartbeat
            self._entry[n], self._watching[n], self._silent[n] = entry, False, 0.0
            seen[n] = self.heard_at.get(producer, 0.0)
        if not producer or not consumer_s:
            return
        heard = self.heard_at.get(producer, 0.0)
        if heard != seen.get(n):
            seen[n] = heard
            if self._watching[n]:  # a silence the host ended itself: it was alive
                self.longest_silence_s = max(self.longest_silence_s, self._silent[n])
            self._silent[n] = 0.0
            if not self._watching[n]:
                self._watching[n] = True
                with self.lock:
                    if d.state is not State.FAULT and d.error_code == HEARTBEAT_CONSUMER_ERROR:
                        d.error_code = 0
                        d.node.emcy.reset(0)  # heard again: the error is gone
            return
        if not self._watching[n]:
            return
        self._silent[n] += step
        if self._silent[n] > consumer_s:
            self._watching[n] = False
            with self.lock:
                self.react(d, producer, self._silent[n])

    def react(self, d: EmulatedDrive, producer: int, silent_s: float) -> None:
        """The drive lost node ``producer``: EMCY 0x8130 and the 0x6007 reaction. Call under
        the drives' lock."""
        option = d.od_int(0x6007)
        self.reactions.append((d.node_id, time.monotonic()))
        # a warning when it cuts torque; after a host that turned torque off and closed (the
        # usual end of a session), a line of information
        cuts = d.state is State.OPERATION_ENABLED and option in (1, 2, 3)
        log.log(
            logging.WARNING if cuts else logging.INFO,
            "drive %d: no heartbeat of node %d for %.2f s: abort connection option %d",
            d.node_id, producer, silent_s, option,
        )  # fmt: skip
        if option == 1:
            d.trip(HEARTBEAT_CONSUMER_ERROR, COMMUNICATION_REGISTER)
            return
        d.error_code = HEARTBEAT_CONSUMER_ERROR
        d.node.emcy.send(HEARTBEAT_CONSUMER_ERROR, COMMUNICATION_REGISTER)
        if option == 2 and d.state in POWERED:
            d.apply_controlword(CW_DISABLE_VOLTAGE)  # SWITCH ON DISABLED, torque off
        elif option == 3 and d.state in POWERED:
            d.apply_controlword(CW_QUICK_STOP)  # QUICK STOP ACTIVE from OPERATION ENABLED
