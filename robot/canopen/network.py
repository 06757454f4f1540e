"""The CANopen network of an arm's drives: the bus layer under ``CanArm``, as
``robot/dynamixel/bus.py`` is under ``DynamixelArm``.

Built on python-can (the bus) and the ``canopen`` library (SDO client, PDO maps, NMT, EMCY,
heartbeat), never hand-written SDO/PDO frames. ``DriveNetwork`` owns:

- the ``canopen.Network`` and one ``RemoteNode`` per drive (``open``, ``close``);
- SDO reads and writes with one-line ``CanNodeError``s naming the node and the object;
- the PDO mapping every drive gets: RPDO1 = controlword 0x6040 + target position 0x607A,
  TPDO1 = statusword 0x6041 + position actual 0x6064, both synchronous, the others disabled;
- NMT: pre-operational for configuration, start, and the wait for every node's OPERATIONAL
  heartbeat;
- what the notifier thread hears, under ``cond``: each node's last TPDO (statusword, position
  in increments, the SYNC it answered, its speed), heartbeat times and NMT states, active EMCY
  errors; ``on_alarm`` is called when a heartbeat leaves OPERATIONAL or an EMCY arrives;
- the control cycle (``cycle``): RPDO1 to every node, a SYNC (``sync_at``: the drives sample
  the positions of synchronous TPDOs at it, CiA 301), then the wait for the TPDOs that answer
  it (at most ``pdo_timeout_s``), late ones counted in ``stats``. One exchange at a time
  (``guard``): a torque-off from another thread preempts a cycle, which gives up at once.

An adapter that fails under the network (unplugged, bus off, a serial error, the notifier
thread ended by one) raises ``CanLinkLost``, a ``robot.errors.LinkLost``, from every exchange
(SDO, NMT, PDO, the cycle), never python-can's or canopen's own exceptions. Garbled lines from
an SLCAN adapter are dropped and counted (``robot.canopen.bus.tolerant_slcan_bus``).
``blind_torque_off`` sends the torque-off frames without listening (over a fresh handle on the
adapter): the last resort when the network cannot be used to confirm anything. Positions
are drive increments here; the arm converts them (``robot.canopen.units.JointScaling``).
"""

from __future__ import annotations

import contextlib
import logging
import os
import struct
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from robot.bus_guard import BusGuard
from robot.canopen import cia402, emcy
from robot.canopen.bus import SLCAN_BITRATES, CanBusError, CanBusSpec, garbled_words, open_bus
from robot.canopen.cia402 import State
from robot.errors import BusError, LinkLost
from robot.torque_guardian import EmergencyPayload

log = logging.getLogger(__name__)


class _SdoTimeoutEcho(logging.Filter):
    """Drops the canopen library's own log line of an SDO transfer it aborts ("Transfer aborted
    by client with code 0x05040000" on a timeout; every abort is followed by its
    ``SdoCommunicationError``): the network and ``ergo bus scan`` turn that error into one
    line naming the node and the object; the library's line came first, two lines for one
    fault (``ergo explore --can slcan:`` on a port of garbage); nor its line before a retry."""

    def filter(self, record: logging.LogRecord) -> bool:
        text = str(record.msg)
        return not (text.startswith("Transfer aborted") or text == "No SDO response received")


logging.getLogger("canopen.sdo.client").addFilter(_SdoTimeoutEcho())

# Attempts of one SDO (python-canopen's MAX_RETRIES; its 1 never retries): a frame lost once is
# sent again (configuration: the same value). Seen: the served stand-in left a reconnect's 0x1017
# unanswered (cause not found).
SDO_ATTEMPTS = 2

PDO_NOT_VALID = 1 << 31  # COB-ID bit 31 of a PDO communication parameter (CiA 301)
# Synchronous transmission type: RPDO applied at the next SYNC, TPDO sent at every SYNC.
TRANS_SYNC = 1
NMT_START_ALL, NMT_PRE_OPERATIONAL = 0x01, 0x80
# COB-ID bases of PDO 1 (CiA 301 predefined connection set: 0x180 + node id for TPDO1, 0x200
# + node id for RPDO1), and of SYNC.
TPDO1_BASE, RPDO1_BASE, SYNC_COB_ID = 0x180, 0x200, 0x080
HEARTBEAT_OPERATIONAL = 5  # NMT state byte in a heartbeat (CiA 301)
# Longest blocking receive of the bus's notifier thread, s: bounds how long disconnect waits
# for it (canopen's default is 1 s; the thread wakes at once when a frame arrives).
NOTIFIER_CYCLE_S = 0.1
# A node that answered no TPDO for this many cycles in a row is lost (guess: one lost frame
# is normal, three in a row are not).
LOST_AFTER_CYCLES = 3
# SDO expedited download of 2 bytes (CiA 301: command specifier 1, n = 2 unused bytes,
# expedited, size indicated), to 0x600 + node id: how a controlword is written without PDOs.
SDO_RX_BASE, SDO_DOWNLOAD_2_BYTES = 0x600, 0x2B
# Garbled adapter lines this recent are named in the messages of lost nodes and unanswered
# SDOs, s (guess: a few heartbeat times).
GARBLED_RECENT_S = 2.0


class CanNodeError(BusError):
    """A CANopen node did not answer, or answered something a CiA 402 drive would not."""


class CanLinkLost(CanBusError, LinkLost):
    """The CAN adapter failed under the arm (unplugged, interface down): a ``LinkLost``,
    which ``robot.Arm`` answers by reconnecting (the bus is reopened by its spec)."""


class CyclePreemptedError(CanBusError):
    """A bus cycle gave up because another thread took the bus to cut torque."""


def safe_decode(statusword: int) -> State | None:
    """The CiA 402 state of a statusword, or None for a coding no state has."""
    try:
        return cia402.decode_statusword(int(statusword))
    except cia402.Cia402Error:
        return None


def slcan_line(can_id: int, data: bytes) -> bytes:
    """A standard-id data frame as an SLCAN (Lawicel) transmit command."""
    return f"t{can_id:03X}{len(data)}{data.hex().upper()}\r".encode()


def sdo_controlword(node_id: int, controlword: int) -> tuple[int, bytes]:
    """The frame (COB-ID, data) of an SDO write of ``controlword`` to 0x6040:0 of a node."""
    return SDO_RX_BASE + node_id, struct.pack(
        "<BHBH2x", SDO_DOWNLOAD_2_BYTES, 0x6040, 0, controlword
    )


@contextlib.contextmanager
def link_errors(bus_spec: CanBusSpec, what: str) -> Any:
    """Turn python-can's and canopen's failures of the adapter (``can.CanError``, an
    ``OSError``, a send on a closed network, the exception that ended the notifier thread, which
    canopen re-raises from every later send) into one-line ``CanLinkLost``."""
    import can

    try:
        yield
    except (can.CanError, OSError) as exc:
        detail = " ".join(str(exc).split()) or type(exc).__name__
        cause = exc.__cause__
        if cause is not None and str(cause):
            detail += f" ({' '.join(str(cause).split())})"
        raise CanLinkLost(f"CAN bus {bus_spec} failed during {what}: {detail}") from exc


class DriveNetwork:
    """The drives of one arm on one CAN bus.

    Args:
        bus_spec: where the bus is.
        node_ids: the drives' node ids, in joint order.
        names: a name per drive for messages (the joint's).
        eds: the drives' EDS (object dictionary).
        sdo_timeout_s: SDO response timeout, s.
        pdo_timeout_s: longest wait for the TPDOs answering a SYNC, s.
        on_alarm: called (from the notifier thread) when a heartbeat leaves OPERATIONAL or an
            EMCY error arrives, once the nodes were started.
    """

    def __init__(
        self,
        bus_spec: CanBusSpec,
        node_ids: Sequence[int],
        names: Sequence[str],
        eds: Path,
        sdo_timeout_s: float,
        pdo_timeout_s: float,
        on_alarm: Callable[[], None] | None = None,
    ) -> None:
        n = len(node_ids)
        self.bus_spec = bus_spec
        self.node_ids = tuple(int(i) for i in node_ids)
        self.names = tuple(names)
        self.eds = Path(eds)
        self.sdo_timeout_s = sdo_timeout_s
        self.pdo_timeout_s = pdo_timeout_s
        self.on_alarm = on_alarm
        # the torque-off bytes shared with a guardian process, refreshed every cycle (set by
        # the arm when its adapter is an SLCAN serial port)
        self.emergency: EmergencyPayload | None = None
        self.network: Any = None
        self.nodes: list[Any] = []
        # What the notifier thread hears, guarded by cond.
        self.cond = threading.Condition()
        self.counts = np.zeros(n, dtype=np.int64)
        self.statusword = np.zeros(n, dtype=np.int64)
        self.rx_seq = np.full(n, -1, dtype=np.int64)
        self.rx_time = np.zeros(n)
        self.velocity = np.zeros(n)  # rad/s once ``velocity_units`` is set, else 0
        self.missed = np.zeros(n, dtype=int)  # consecutive cycles without a TPDO
        self.late_since = np.full(n, np.nan)  # first unanswered SYNC, monotonic s
        self.emcy_active: list[tuple[int, int] | None] = [None] * n
        self.heartbeat_at = np.zeros(n)
        self.nmt_state = np.zeros(n, dtype=int)
        #: when the host last found itself behind the adapter (frames unread, or its own
        #: stall: ``robot.canopen.health``), monotonic s; 0: never
        self.behind_at = 0.0
        #: (increments per revolution, direction) per node, to turn TPDOs into joint speeds
        self.velocity_units: tuple[np.ndarray, np.ndarray] | None = None
        # What the next cycle sends: controlword and target of each node, the SYNC counter.
        self.cw = np.zeros(n, dtype=np.int64)
        self.target = np.zeros(n, dtype=np.int64)
        self.seq, self.sync_at = 0, 0.0  # the last SYNC's number and monotonic time, s
        self.sync_since_read = False
        # cycles run, cycles where a node's TPDO missed pdo_timeout_s, TPDOs missing in them
        self.stats = {"cycles": 0, "late_cycles": 0, "missing_tpdos": 0}
        self._garbled_before = 0  # garbled lines of the buses closed before the current one
        self.started = False
        self.guard = BusGuard(
            lambda: CyclePreemptedError(
                f"bus cycle on {self.bus_spec} given up: another thread is cutting torque"
            ),
            wake=self._notify,
        )

    def who(self, i: int) -> str:
        """Node ``i`` in words: ``node 3 (m3)``."""
        return f"node {self.node_ids[i]} ({self.names[i]})"

    def _notify(self) -> None:
        with self.cond:
            self.cond.notify_all()

    # ---- opening and closing ---------------------------------------------------------------
    def reset_state(self) -> None:
        """Forget everything heard on a previous connection."""
        with self.cond:
            self.rx_seq[:] = -1
            self.missed[:] = 0
            self.late_since[:] = np.nan
            self.statusword[:] = 0
            self.velocity[:] = 0.0
            self.emcy_active = [None] * len(self.node_ids)
            self.nmt_state[:] = 0
            self.behind_at = 0.0
        self.sync_since_read = False

    def open(self) -> None:
        """Open the bus and the network, one ``RemoteNode`` per drive with its callbacks."""
        import canopen

        bus = open_bus(self.bus_spec)
        self.network = canopen.Network(bus)
        self.network.NOTIFIER_CYCLE = NOTIFIER_CYCLE_S
        self.network.connect()
        self.nodes = []
        for i, nid in enumerate(self.node_ids):
            node = canopen.RemoteNode(nid, canopen.import_od(str(self.eds), nid))
            node.sdo.RESPONSE_TIMEOUT = self.sdo_timeout_s
            node.sdo.MAX_RETRIES = SDO_ATTEMPTS
            self.network.add_node(node)
            node.nmt.add_heartbeat_callback(lambda st, i=i: self._on_heartbeat(i, st))
            node.emcy.add_callback(lambda err, i=i: self._on_emcy(i, err))
            self.nodes.append(node)

    def close(self) -> None:
        """Close the network and its bus; never raises (logged)."""
        self.started = False
        if self.network is not None:
            self._garbled_before += self._garbled_now()
            try:
                if self.network.notifier is not None:
                    self.network.notifier.exception = None  # reported already, by a send
                self.network.disconnect()
            except Exception as exc:
                log.error("closing CAN bus %s: %s", self.bus_spec, exc)
            self.network = None

    def _garbled_now(self) -> int:
        bus = None if self.network is None else self.network.bus
        return int(getattr(bus, "garbled_lines", 0))

    @property
    def garbled_lines(self) -> int:
        """Lines from the adapter dropped as garbage since this network was made."""
        return self._garbled_before + self._garbled_now()

    @property
    def garbled_at(self) -> float:
        """When the adapter last sent a garbled line (``time.monotonic`` s; 0: never)."""
        bus = None if self.network is None else self.network.bus
        return float(getattr(bus, "garbled_at", 0.0))

    def garbled_note(self) -> str:
        """``"; N garbled lines from the adapter ..."`` when some came lately, else ``""``:
        what a message about silent nodes adds when the line itself is the likely cause."""
        at = self.garbled_at
        if not at or time.monotonic() - at > GARBLED_RECENT_S:
            return ""
        return garbled_words(self.garbled_lines)

    def _require_open(self, what: str) -> None:
        if self.network is None or not self.nodes:
            raise CanLinkLost(f"CAN bus {self.bus_spec} is not open ({what})")

    # ---- SDO -------------------------------------------------------------------------------
    def sdo_read(self, i: int, index: int, sub: int = 0) -> int:
        """Object ``index``:``sub`` of node ``i``, read by SDO."""
        from canopen.sdo import SdoAbortedError, SdoCommunicationError

        self._require_open(f"SDO read of 0x{index:04X}:{sub}")
        node = self.nodes[i]
        try:
            with link_errors(self.bus_spec, f"SDO read of 0x{index:04X}:{sub}"):
                var = node.sdo[index] if sub == 0 else node.sdo[index][sub]
                return int(var.raw)
        except SdoCommunicationError as exc:
            raise CanNodeError(
                f"{self.who(i)} does not answer SDO 0x{index:04X}:{sub} on {self.bus_spec} "
                f"({exc}): powered? right node id and bitrate?{self.garbled_note()}"
            ) from exc
        except (SdoAbortedError, KeyError) as exc:
            raise CanNodeError(f"{self.who(i)} refused to read 0x{index:04X}:{sub}: {exc}") from exc

    def sdo_write(self, i: int, index: int, sub: int, value: int) -> None:
        """Write ``value`` to object ``index``:``sub`` of node ``i`` by SDO."""
        from canopen.sdo import SdoAbortedError, SdoCommunicationError

        self._require_open(f"SDO write of 0x{index:04X}:{sub}")
        node = self.nodes[i]
        try:
            with link_errors(self.bus_spec, f"SDO write of 0x{index:04X}:{sub}"):
                var = node.sdo[index] if sub == 0 else node.sdo[index][sub]
                var.raw = int(value)
        except SdoCommunicationError as exc:
            raise CanNodeError(
                f"{self.who(i)} does not answer SDO 0x{index:04X}:{sub} on {self.bus_spec} "
                f"({exc}){self.garbled_note()}"
            ) from exc
        except (SdoAbortedError, KeyError) as exc:
            raise CanNodeError(
                f"{self.who(i)} refused 0x{index:04X}:{sub} = {value}: {exc}"
            ) from exc

    def pre_operational(self) -> None:
        """NMT pre-operational on every node (PDOs off, for configuration)."""
        self._require_open("NMT pre-operational")
        with link_errors(self.bus_spec, "NMT pre-operational"):
            self.network.nmt.send_command(NMT_PRE_OPERATIONAL)

    def map_pdos(self, i: int) -> None:
        """RPDO1 = controlword + target position, TPDO1 = statusword + position actual, both
        synchronous; other PDOs of the EDS disabled."""
        from canopen.sdo import SdoAbortedError, SdoCommunicationError

        self._require_open("PDO mapping")
        try:
            with link_errors(self.bus_spec, f"PDO mapping of {self.who(i)}"):
                self._map_pdos(i)
        except (SdoCommunicationError, SdoAbortedError) as exc:
            raise CanNodeError(f"{self.who(i)}: PDO mapping failed: {exc}") from exc

    def _map_pdos(self, i: int) -> None:
        node, nid = self.nodes[i], self.node_ids[i]
        for maps, base, entries in (
            (node.rpdo, RPDO1_BASE, (0x6040, 0x607A)),
            (node.tpdo, TPDO1_BASE, (0x6041, 0x6064)),
        ):
            for number, pdo in maps.map.items():
                if number == 1:
                    continue
                cob = int(pdo.com_record[1].raw)
                if not cob & PDO_NOT_VALID:
                    pdo.com_record[1].raw = cob | PDO_NOT_VALID
            pdo = maps.map[1]
            pdo.clear()
            for index in entries:
                pdo.add_variable(index)
            pdo.cob_id = base + nid
            pdo.trans_type = TRANS_SYNC
            pdo.enabled = True
            pdo.save()
        node.tpdo.map[1].add_callback(lambda pdo, i=i: self._on_tpdo(i, pdo))

    def start(self, heartbeat_s: float, state_timeout_s: float) -> None:
        """NMT start all, then wait for a heartbeat from every node saying OPERATIONAL (at
        least three heartbeat times, or ``state_timeout_s``)."""
        now = time.monotonic()
        with self.cond:
            self.heartbeat_at[:] = now
            self.nmt_state[:] = 0
        self._require_open("NMT start")
        with link_errors(self.bus_spec, "NMT start"):
            self.network.nmt.send_command(NMT_START_ALL)
        deadline = now + max(3 * heartbeat_s, state_timeout_s)
        with self.cond:
            ok = self.cond.wait_for(
                lambda: bool(np.all(self.nmt_state == HEARTBEAT_OPERATIONAL)),
                max(0.0, deadline - time.monotonic()),
            )
            if not ok:
                silent = np.flatnonzero(self.nmt_state != HEARTBEAT_OPERATIONAL)
                raise CanNodeError(
                    f"no OPERATIONAL heartbeat from {', '.join(self.who(i) for i in silent)} "
                    f"after NMT start{self.garbled_note()}"
                )
        self.started = True

    # ---- what the notifier thread hears ----------------------------------------------------
    def _on_tpdo(self, i: int, pdo: Any) -> None:
        sw = int(pdo[0x6041].raw)
        counts = int(pdo[0x6064].raw)
        now = time.monotonic()
        with self.cond:
            dt = now - self.rx_time[i]
            if self.rx_seq[i] >= 0 and dt > 0 and self.velocity_units is not None:
                cpr, directions = self.velocity_units
                delta = (counts - self.counts[i]) * 2 * np.pi / cpr[i] * directions[i]
                self.velocity[i] = delta / dt
            self.statusword[i] = sw
            self.counts[i] = counts
            self.rx_seq[i] = self.seq
            self.rx_time[i] = now
            self.missed[i] = 0
            self.late_since[i] = np.nan
            self.cond.notify_all()

    def _on_heartbeat(self, i: int, state: int) -> None:
        with self.cond:
            self.heartbeat_at[i] = time.monotonic()
            self.nmt_state[i] = state
            self.cond.notify_all()
        if state != HEARTBEAT_OPERATIONAL and self.started and self.on_alarm is not None:
            self.on_alarm()

    def _on_emcy(self, i: int, err: Any) -> None:
        code, register = int(err.code), int(err.register)
        with self.cond:
            self.emcy_active[i] = None if code & 0xFF00 == 0 else (code, register)
        stops = bool(code & 0xFF00) and self.on_alarm is not None
        # an EMCY that stops the arm is told once, by its safety stop; an error reset (a drive
        # hearing the host again after its watch of the host timed out) only with --verbose;
        # others as a warning
        quiet = stops or not code & 0xFF00
        log.log(logging.DEBUG if quiet else logging.WARNING, "%s: %s", self.who(i),
                emcy.describe(code, register))  # fmt: skip
        if stops:
            self.on_alarm()

    # ---- the control cycle -----------------------------------------------------------------
    def torque_off_lines(self) -> bytes:
        """What cuts every drive's torque, as SLCAN lines (Lawicel ``tIIILDD..\\r``): RPDO1 to
        each node with "disable voltage" (``cia402.CW_TORQUE_OFF``: to SWITCH ON DISABLED from
        every state whose power stage is on, quick stop active included; no change elsewhere)
        and its current target, then a SYNC (the RPDOs are synchronous). The bytes a
        torque-off guardian writes to the adapter (``robot.torque_guardian``)."""
        lines = [
            slcan_line(RPDO1_BASE + nid, struct.pack("<Hi", cia402.CW_TORQUE_OFF, int(t)))
            for nid, t in zip(self.node_ids, self.target, strict=True)
        ]
        return b"".join([*lines, slcan_line(SYNC_COB_ID, b"")])

    def torque_off_frames(self) -> list[tuple[int, bytes]]:
        """Every frame of a torque off that needs no answer, (COB-ID, data): RPDO1 "disable
        voltage" with the current target to each node and a SYNC (drives in NMT OPERATIONAL
        apply it at the SYNC), then an SDO write of "disable voltage" to each node's
        controlword (applied at once in PRE-OPERATIONAL too: a drive that was reset or never
        configured; its answer is not awaited). A drive in OPERATION ENABLED, QUICK STOP
        ACTIVE, SWITCHED ON or READY TO SWITCH ON goes to SWITCH ON DISABLED (CiA 402-2
        transitions 9, 12, 10, 7: ``cia402.CW_TORQUE_OFF``); in the other states it is no
        transition."""
        frames = [
            (RPDO1_BASE + nid, struct.pack("<Hi", cia402.CW_TORQUE_OFF, int(t)))
            for nid, t in zip(self.node_ids, self.target, strict=True)
        ]
        frames.append((SYNC_COB_ID, b""))
        frames += [sdo_controlword(nid, cia402.CW_TORQUE_OFF) for nid in self.node_ids]
        return frames

    def blind_torque_off(self) -> str:
        """Send ``torque_off_frames`` listening to nothing: the last resort when the drives
        cannot confirm a torque off (lost nodes, a garbled line, the notifier thread ended, the
        network closed after a failed reconnection). On the open bus if it still sends; else on
        a fresh handle of the adapter: on an SLCAN serial port the lines are written straight
        to the device after the commands that (re)open the CAN channel (``C``, ``Sn``, ``O``:
        a re-plugged adapter starts closed), other interfaces get a new python-can bus. Call it
        holding ``guard``. Never raises.

        Returns:
            what was done, for a one-line message: "sent to node(s) 1, ..., 6 without
            confirmation (...)" or "could not be sent (reason)".
        """
        import can

        frames = self.torque_off_frames()
        ids = ", ".join(str(n) for n in self.node_ids)
        messages = [can.Message(arbitration_id=c, data=d, is_extended_id=False) for c, d in frames]
        network = self.network
        if network is not None and network.bus is not None:
            try:  # the open bus, whatever its notifier thread's state
                with network.send_lock:
                    for msg in messages:
                        network.bus.send(msg)
                return (
                    f"sent to node(s) {ids} without confirmation (disable voltage by RPDO and SDO)"
                )
            except Exception as exc:
                log.warning("blind torque off on the open bus %s: %s", self.bus_spec, exc)
        try:
            path = self.bus_spec.channel.split("@", 1)[0]
            if self.bus_spec.interface == "slcan" and path.startswith("/"):
                rate = self.bus_spec.bitrate or 1_000_000
                opening = f"C\rS{SLCAN_BITRATES.index(rate)}\rO\r".encode()
                data = opening + b"".join(slcan_line(cid, d) for cid, d in frames)
                fd = os.open(path, os.O_WRONLY | os.O_NOCTTY | os.O_NONBLOCK | os.O_CLOEXEC)
                try:
                    os.write(fd, data)
                finally:
                    os.close(fd)
            else:
                bus = open_bus(self.bus_spec)
                try:
                    for msg in messages:
                        bus.send(msg)
                finally:
                    bus.shutdown()
        except Exception as exc:
            detail = " ".join(str(exc).split()) or type(exc).__name__
            log.error("blind torque off on %s failed: %s", self.bus_spec, detail)
            return f"could not be sent ({detail})"
        return (
            f"sent to node(s) {ids} on a reopened adapter without confirmation (disable "
            f"voltage by RPDO and SDO)"
        )

    def cycle(self, send_rpdo: bool = True, on_sent: Callable[[], None] | None = None) -> None:
        """RPDO1 to every node (``cw`` + ``target``), then a SYNC, then wait for the TPDOs.
        Call it inside ``guard.hold()``. ``on_sent`` is called once the RPDOs and the SYNC
        (at which the drives apply them) are sent, before the wait.

        Raises:
            CanLinkLost: the adapter failed (unplugged, bus off, serial error).
            CyclePreemptedError: another thread is cutting torque.
        """
        self.guard.check()
        self._require_open("bus cycle")
        if self.emergency is not None:
            self.emergency.set(self.torque_off_lines())
        with self.cond:
            self.seq += 1
            seq = self.seq
        with link_errors(self.bus_spec, "a bus cycle"):
            if send_rpdo:
                for i, node in enumerate(self.nodes):
                    pdo = node.rpdo.map[1]
                    pdo[0x6040].raw = int(self.cw[i])
                    pdo[0x607A].raw = int(self.target[i])
                    pdo.transmit()
            self.network.sync.transmit()
            self.sync_at = time.monotonic()
            if on_sent is not None:
                on_sent()
        self.stats["cycles"] += 1
        with self.cond:
            self.cond.wait_for(
                lambda: bool(np.all(self.rx_seq >= seq)) or self.guard.preempted,
                self.pdo_timeout_s,
            )
            self.guard.check()
            late = self.rx_seq < seq
            if late.any():
                self.stats["late_cycles"] += 1
                self.stats["missing_tpdos"] += int(late.sum())
            self.missed[late] += 1
            self.late_since[late & np.isnan(self.late_since)] = self.sync_at
        self.sync_since_read = True

    def first_positions(self, timeout_s: float) -> None:
        """SYNC until every node has sent a TPDO (or ``timeout_s`` passed)."""
        deadline = time.monotonic() + timeout_s
        while True:
            self.cycle(send_rpdo=False)
            with self.cond:
                never = [self.who(i) for i in np.flatnonzero(self.rx_seq < 0)]
            if not never:
                with self.cond:
                    self.missed[:] = 0
                    self.late_since[:] = np.nan
                return
            if time.monotonic() > deadline:
                raise CanNodeError(
                    f"no TPDO from {', '.join(never)} after NMT start and "
                    f"{timeout_s:.1f} s of SYNCs"
                )

    def lost(self, heartbeat_limit_s: float) -> set[int]:
        """Nodes that cannot confirm anything: heartbeat silent for over ``heartbeat_limit_s``,
        or no TPDO for ``LOST_AFTER_CYCLES`` cycles."""
        now = time.monotonic()
        with self.cond:
            silent = now - self.heartbeat_at > heartbeat_limit_s
            return set(np.flatnonzero(silent | (self.missed >= LOST_AFTER_CYCLES)).tolist())

    def states(self) -> list[State | None]:
        """The CiA 402 state of every node from its last statusword (None: undecodable)."""
        with self.cond:
            return [safe_decode(sw) for sw in self.statusword]

    def states_are(self, state: State) -> np.ndarray:
        """Which nodes are in ``state``, shape (n,) bool."""
        return np.array([s is state for s in self.states()])
