"""``CanArm``: the ``robot.Arm`` interface on six CiA 402 servo drives over CANopen.

Built on python-can (the bus) and the ``canopen`` library (SDO client, PDO maps, NMT, EMCY,
heartbeat), never hand-written SDO/PDO frames. At connect:

1. every node answers an SDO read of its device type 0x1000 (low word 402: a drive);
2. units: increments per revolution from 0x608F (position encoder resolution);
3. SDO configuration: mode of operation 0x6060 = 8 (cyclic synchronous position), software
   position limits 0x607D from the arm spec, producer heartbeat 0x1017, optionally the
   following error window 0x6065; PDO mapping RPDO1 = controlword 0x6040 + target position
   0x607A, TPDO1 = statusword 0x6041 + position actual 0x6064, both synchronous;
4. NMT start (OPERATIONAL), then one SYNC to read the drives' states and positions.

Each command is one cycle: RPDO1 to every node, then a SYNC; the drives apply the targets at
the SYNC and answer with TPDO1. ``read`` returns the positions of the latest TPDOs (sending a
SYNC itself if no command did since the last read). Torque on/off walks the CiA 402 state
machine (shutdown -> switch on -> operation enabled; operation disabled for torque off) through
the controlword in RPDO1.

Safety (on top of the base class's clamping, watchdog and torque off on exit):
- heartbeat consumer: a node silent for longer than 1.5 x its heartbeat time stops the arm;
- EMCY messages and drives seen in FAULT stop the arm, with the decoded error;
- a node that answers no SYNC for ``max_position_age_s`` stops the arm;
A stop turns torque off on every node at once (from a monitor thread) and makes the next
``read``/``command`` raise ``SafetyStop`` with a one-line reason; ``reset_faults()`` clears it.
A torque off from another thread (the monitor, the signal watcher of
``robot.safety.torque_off_on_signals``) preempts the cycle in progress, which gives up at once
instead of waiting out its TPDO timeout.

Link loss (the adapter fails: ``CanLinkLost``): ``robot.Arm`` reconnects (the bus reopened from
its spec, the drives configured again, positions read, torque re-enabled holding them) at most
``RecoveryPolicy.attempts`` times, else a ``SafetyStop``. Late TPDOs are counted
(``fault_counts``: ``can_late_cycles``, ``can_missing_tpdos``); the positions are then one
cycle old, and a node late for ``max_position_age_s`` stops the arm.

Units: joint positions in rad; drive positions in increments (see ``units.JointScaling``).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from robot.arm import Arm, JointState, RecoveryPolicy
from robot.canopen import cia402, emcy
from robot.canopen.bus import (
    DEFAULT_BITRATE,
    CanBusError,
    CanBusSpec,
    open_bus,
    parse_can_spec,
)
from robot.canopen.cia402 import State
from robot.canopen.units import JointScaling
from robot.errors import BusError, LinkLost, SafetyStop
from robot.safety import Watchdog
from robot.spec import ArmSpec, ergo_jr_spec

log = logging.getLogger(__name__)

EDS_PATH = Path(__file__).resolve().parent / "ergo_drive.eds"
CSP = 8  # modes of operation 0x6060: cyclic synchronous position (CiA 402-2)
DEVICE_PROFILE_402 = 402  # low word of 0x1000 for a drive (CiA 402-2)
PDO_NOT_VALID = 1 << 31  # COB-ID bit 31 of a PDO communication parameter (CiA 301)
# Synchronous transmission type: RPDO applied at the next SYNC, TPDO sent at every SYNC.
TRANS_SYNC = 1
NMT_START_ALL, NMT_PRE_OPERATIONAL = 0x01, 0x80
HEARTBEAT_OPERATIONAL = 5  # NMT state byte in a heartbeat (CiA 301)
# Longest blocking receive of the bus's notifier thread, s: bounds how long disconnect waits
# for it (canopen's default is 1 s; the thread wakes at once when a frame arrives).
NOTIFIER_CYCLE_S = 0.1


class CanNodeError(BusError):
    """A CANopen node did not answer, or answered something a CiA 402 drive would not."""


class CanLinkLost(CanBusError, LinkLost):
    """The CAN adapter failed under the arm (unplugged, interface down): a ``LinkLost``,
    which ``robot.Arm`` answers by reconnecting (the bus is reopened by its spec)."""


class CyclePreemptedError(CanBusError):
    """A bus cycle gave up because another thread took the bus to cut torque."""


@dataclass(frozen=True)
class CanArmConfig:
    """Settings of a ``CanArm``; defaults are guesses for small servo drives at 1 Mbit/s.

    Attributes:
        node_ids: CANopen node id of each joint's drive (None: the spec's servo ids).
        directions: +1/-1 per joint (drive counts grow with the joint angle or against it).
        offsets: joint angle at drive position 0, per joint, rad.
        heartbeat_ms: producer heartbeat time written to each node's 0x1017, ms (guess: 100 ms
            notices a dead node within 150 ms, at 6 frames per 100 ms of bus load).
        heartbeat_factor: a node is lost when silent for this times its heartbeat time (1.5,
            the brief; CiA 301 leaves the consumer time to the integrator).
        pdo_timeout_s: longest wait for the TPDOs answering a SYNC, s (guess: a 1 Mbit/s bus
            carries the 13 frames of a cycle in about 1.5 ms; an SLCAN pty adds a few ms).
        max_position_age_s: the arm stops when a node has answered no SYNC for this long, s
            (guess: 20 control periods at 40 Hz; the drive itself keeps following its last
            target meanwhile, and a dead node is caught sooner by its heartbeat).
        state_timeout_s: longest time for the drives to reach a CiA 402 state, s (guess: real
            drives take up to a few hundred ms to switch on, e.g. to release a brake; the
            emulator behind a pty on a loaded machine was measured taking over 1 s).
        sdo_timeout_s: SDO response timeout, s (canopen's default is 0.3 s).
        following_error_window: if set, written to 0x6065, rad (None: leave the drive's).
        eds: the drives' EDS (object dictionary).
    """

    node_ids: tuple[int, ...] | None = None
    directions: tuple[float, ...] | None = None
    offsets: tuple[float, ...] | None = None
    heartbeat_ms: int = 100
    heartbeat_factor: float = 1.5
    pdo_timeout_s: float = 0.02
    max_position_age_s: float = 0.5
    state_timeout_s: float = 3.0
    sdo_timeout_s: float = 0.3
    following_error_window: float | None = None
    eds: Path = EDS_PATH


class CanArm(Arm):
    """The arm on a CANopen bus of CiA 402 drives.

    Args:
        can: where the bus is: ``INTERFACE:CHANNEL`` (``socketcan:can0``,
            ``slcan:/dev/ttyACM0``, ``virtual:NAME``) or a ``CanBusSpec``.
        bitrate: bit/s for interfaces that take one.
        spec: joints and limits (default: the Ergo Jr).
        config: node ids, units, timeouts.
        watchdog: the base class's thermal/load watchdog.
        recovery: reconnection policy when the adapter fails (``robot.arm.RecoveryPolicy``).
    """

    def __init__(
        self,
        can: str | CanBusSpec,
        bitrate: int | None = DEFAULT_BITRATE,
        spec: ArmSpec | None = None,
        config: CanArmConfig | None = None,
        watchdog: Watchdog | None = None,
        recovery: RecoveryPolicy | None = None,
    ) -> None:
        super().__init__(spec or ergo_jr_spec(), watchdog, recovery)
        self.bus_spec = can if isinstance(can, CanBusSpec) else parse_can_spec(can, bitrate)
        self.config = config or CanArmConfig()
        n = self.spec.n
        ids = self.config.node_ids or tuple(self.spec.ids)
        if len(ids) != n or len(set(ids)) != n or not all(1 <= i <= 127 for i in ids):
            raise ValueError(f"need {n} distinct CANopen node ids in 1..127, got {list(ids)}")
        self.node_ids = tuple(int(i) for i in ids)
        self._directions = np.asarray(self.config.directions or (1.0,) * n, dtype=float)
        self._offsets = np.asarray(self.config.offsets or (0.0,) * n, dtype=float)
        JointScaling(np.ones(n), self._directions, self._offsets)  # validate early
        if not Path(self.config.eds).is_file():
            raise ValueError(f"EDS file not found: {self.config.eds}")
        if self.config.heartbeat_ms < 1 or self.config.heartbeat_factor <= 1.0:
            raise ValueError(
                f"heartbeat_ms must be >= 1 and heartbeat_factor > 1 (got "
                f"{self.config.heartbeat_ms}, {self.config.heartbeat_factor}): a node without "
                f"a heartbeat cannot be watched"
            )
        self.scaling: JointScaling | None = None
        self.network: Any = None
        self.nodes: list[Any] = []
        # Cyclic state, guarded by _cond (written by the notifier thread).
        self._cond = threading.Condition()
        self._counts = np.zeros(n, dtype=np.int64)
        self._statusword = np.zeros(n, dtype=np.int64)
        self._rx_seq = np.full(n, -1, dtype=np.int64)
        self._rx_time = np.zeros(n)
        self._velocity = np.zeros(n)
        self._missed = np.zeros(n, dtype=int)  # consecutive cycles without a TPDO
        self._late_since = np.full(n, np.nan)  # first unanswered SYNC, monotonic s
        self._emcy_active: list[tuple[int, int] | None] = [None] * n
        self._heartbeat_at = np.zeros(n)
        self._nmt_state = np.zeros(n, dtype=int)
        self._heartbeat_s = self.config.heartbeat_ms / 1000.0
        # Command state: controlword and target of each node, the SYNC counter.
        self._cw = np.zeros(n, dtype=np.int64)
        self._target = np.zeros(n, dtype=np.int64)
        self._seq = 0
        self._sync_since_read = False
        # Safety: one I/O cycle at a time; a signal inside our own cycle is deferred.
        self._io_lock = threading.RLock()
        self._io_owner: int | None = None
        self._pending_off = False
        # Set while another thread cuts torque: a cycle in progress gives up at once.
        self._preempt = threading.Event()
        self._preempt_by: int | None = None
        # cycles run, cycles where a node's TPDO missed pdo_timeout_s, TPDOs missing in them
        self.stats = {"cycles": 0, "late_cycles": 0, "missing_tpdos": 0}
        self._stop_reason: str | None = None
        self._trip_lock = threading.Lock()
        self._tripping = threading.Event()
        self._started = False
        self._wake = threading.Event()
        self._closing = threading.Event()
        self._monitor: threading.Thread | None = None

    # ---- names -----------------------------------------------------------------------------
    def _who(self, i: int) -> str:
        return f"node {self.node_ids[i]} ({self.spec.joints[i].name})"

    # ---- connect ---------------------------------------------------------------------------
    def _reset_state(self) -> None:
        """Forget everything heard on a previous connection."""
        with self._cond:
            self._rx_seq[:] = -1
            self._missed[:] = 0
            self._late_since[:] = np.nan
            self._statusword[:] = 0
            self._velocity[:] = 0.0
            self._emcy_active = [None] * self.spec.n
            self._nmt_state[:] = 0
        self._stop_reason = None
        self._sync_since_read = False
        self._pending_off = False

    def _connect(self) -> None:
        import canopen

        self._reset_state()
        bus = open_bus(self.bus_spec)
        self.network = canopen.Network(bus)
        self.network.NOTIFIER_CYCLE = NOTIFIER_CYCLE_S
        try:
            with self._io():
                self.network.connect()
                self.nodes = []
                for i, nid in enumerate(self.node_ids):
                    node = canopen.RemoteNode(nid, canopen.import_od(str(self.config.eds), nid))
                    node.sdo.RESPONSE_TIMEOUT = self.config.sdo_timeout_s
                    self.network.add_node(node)
                    node.nmt.add_heartbeat_callback(lambda st, i=i: self._on_heartbeat(i, st))
                    node.emcy.add_callback(lambda err, i=i: self._on_emcy(i, err))
                    self.nodes.append(node)
                self._configure()
                self._start_nodes()
            self._start_monitor()
            with self._io():
                self._first_positions()
            self._torque = bool(np.all(self._states_are(State.OPERATION_ENABLED)))
            self._cw[:] = np.where(
                self._states_are(State.OPERATION_ENABLED), cia402.CW_ENABLE_OPERATION, 0
            )
            with self._cond:
                self._target[:] = self._counts
        except BaseException:
            self._stop_monitor()
            self._shutdown_network()
            raise

    def _sdo_read(self, i: int, index: int, sub: int = 0) -> int:
        from canopen.sdo import SdoAbortedError, SdoCommunicationError

        node = self.nodes[i]
        try:
            var = node.sdo[index] if sub == 0 else node.sdo[index][sub]
            return int(var.raw)
        except SdoCommunicationError as exc:
            raise CanNodeError(
                f"{self._who(i)} does not answer SDO 0x{index:04X}:{sub} on {self.bus_spec} "
                f"({exc}): powered? right node id and bitrate?"
            ) from exc
        except (SdoAbortedError, KeyError) as exc:
            raise CanNodeError(
                f"{self._who(i)} refused to read 0x{index:04X}:{sub}: {exc}"
            ) from exc

    def _sdo_write(self, i: int, index: int, sub: int, value: int) -> None:
        from canopen.sdo import SdoAbortedError, SdoCommunicationError

        node = self.nodes[i]
        try:
            var = node.sdo[index] if sub == 0 else node.sdo[index][sub]
            var.raw = int(value)
        except SdoCommunicationError as exc:
            raise CanNodeError(
                f"{self._who(i)} does not answer SDO 0x{index:04X}:{sub} on {self.bus_spec} ({exc})"
            ) from exc
        except (SdoAbortedError, KeyError) as exc:
            raise CanNodeError(
                f"{self._who(i)} refused 0x{index:04X}:{sub} = {value}: {exc}"
            ) from exc

    def _configure(self) -> None:
        """SDO configuration of every node (NMT pre-operational first: PDOs off)."""
        self.network.nmt.send_command(NMT_PRE_OPERATIONAL)
        cpr = np.zeros(self.spec.n)
        for i in range(self.spec.n):
            device_type = self._sdo_read(i, 0x1000)
            if device_type & 0xFFFF != DEVICE_PROFILE_402:
                raise CanNodeError(
                    f"{self._who(i)} is not a CiA 402 drive (device type 0x{device_type:08X})"
                )
            increments, revolutions = self._sdo_read(i, 0x608F, 1), self._sdo_read(i, 0x608F, 2)
            if increments <= 0 or revolutions <= 0:
                raise CanNodeError(
                    f"{self._who(i)} reports a position encoder resolution of "
                    f"{increments}/{revolutions} increments per revolution"
                )
            cpr[i] = increments / revolutions
        self.scaling = JointScaling(cpr, self._directions, self._offsets)
        lo, hi = self.scaling.limits_to_counts(self.spec.lower, self.spec.upper)
        for i in range(self.spec.n):
            if self._sdo_read(i, 0x6060) != CSP:  # a drive may refuse it while enabled
                self._sdo_write(i, 0x6060, 0, CSP)
            self._sdo_write(i, 0x607D, 1, int(lo[i]))
            self._sdo_write(i, 0x607D, 2, int(hi[i]))
            self._sdo_write(i, 0x1017, 0, self.config.heartbeat_ms)
            if self.config.following_error_window is not None:
                window = self.config.following_error_window * cpr[i] / (2 * np.pi)
                self._sdo_write(i, 0x6065, 0, round(window))
            self._map_pdos(i)

    def _map_pdos(self, i: int) -> None:
        """RPDO1 = controlword + target position, TPDO1 = statusword + position actual, both
        synchronous; other PDOs of the EDS disabled."""
        from canopen.sdo import SdoAbortedError, SdoCommunicationError

        node, nid = self.nodes[i], self.node_ids[i]
        try:
            for maps, base, entries in (
                (node.rpdo, 0x200, (0x6040, 0x607A)),
                (node.tpdo, 0x180, (0x6041, 0x6064)),
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
        except (SdoCommunicationError, SdoAbortedError) as exc:
            raise CanNodeError(f"{self._who(i)}: PDO mapping failed: {exc}") from exc

    def _start_nodes(self) -> None:
        """NMT start all, then wait for a heartbeat from every node saying OPERATIONAL."""
        now = time.monotonic()
        with self._cond:
            self._heartbeat_at[:] = now
            self._nmt_state[:] = 0
        self.network.nmt.send_command(NMT_START_ALL)
        deadline = now + max(3 * self._heartbeat_s, self.config.state_timeout_s)
        with self._cond:
            ok = self._cond.wait_for(
                lambda: bool(np.all(self._nmt_state == HEARTBEAT_OPERATIONAL)),
                max(0.0, deadline - time.monotonic()),
            )
            if not ok:
                silent = [self._who(i) for i in np.flatnonzero(self._nmt_state != 5)]
                raise CanNodeError(
                    f"no OPERATIONAL heartbeat from {', '.join(silent)} after NMT start"
                )
        self._started = True

    # ---- disconnect ------------------------------------------------------------------------
    def _disconnect(self) -> None:
        self._stop_monitor()
        self._shutdown_network()

    def _stop_monitor(self) -> None:
        self._closing.set()
        self._wake.set()
        if self._monitor is not None and self._monitor is not threading.current_thread():
            self._monitor.join(timeout=2.0)
        self._monitor = None

    def _shutdown_network(self) -> None:
        self._started = False
        if self.network is not None:
            try:
                self.network.disconnect()
            except Exception as exc:
                log.error("closing CAN bus %s: %s", self.bus_spec, exc)
            self.network = None

    # ---- bus callbacks (notifier thread) ---------------------------------------------------
    def _on_tpdo(self, i: int, pdo: Any) -> None:
        sw = int(pdo[0x6041].raw)
        counts = int(pdo[0x6064].raw)
        now = time.monotonic()
        with self._cond:
            dt = now - self._rx_time[i]
            if self._rx_seq[i] >= 0 and dt > 0 and self.scaling is not None:
                cpr = self.scaling.counts_per_rev[i]
                delta = (counts - self._counts[i]) * 2 * np.pi / cpr * self._directions[i]
                self._velocity[i] = delta / dt
            self._statusword[i] = sw
            self._counts[i] = counts
            self._rx_seq[i] = self._seq
            self._rx_time[i] = now
            self._missed[i] = 0
            self._late_since[i] = np.nan
            self._cond.notify_all()

    def _on_heartbeat(self, i: int, state: int) -> None:
        with self._cond:
            self._heartbeat_at[i] = time.monotonic()
            self._nmt_state[i] = state
            self._cond.notify_all()
        if state != HEARTBEAT_OPERATIONAL and self._started:
            self._wake.set()

    def _on_emcy(self, i: int, err: Any) -> None:
        code, register = int(err.code), int(err.register)
        with self._cond:
            self._emcy_active[i] = None if code & 0xFF00 == 0 else (code, register)
        log.warning("%s: %s", self._who(i), emcy.describe(code, register))
        if code & 0xFF00:
            self._wake.set()

    # ---- safety monitor --------------------------------------------------------------------
    def _start_monitor(self) -> None:
        self._closing.clear()
        self._monitor = threading.Thread(
            target=self._monitor_loop, name="canarm-monitor", daemon=True
        )
        self._monitor.start()

    def _monitor_loop(self) -> None:
        period = max(0.005, self._heartbeat_s / 4)
        while not self._closing.is_set():
            self._wake.wait(period)
            self._wake.clear()
            if self._closing.is_set():
                break
            if self._stop_reason is None:
                reason = self._health()
                if reason is not None:
                    self._trip(reason)

    def _health(self) -> str | None:
        """A one-line reason to stop the arm, or None when every node is healthy."""
        if not self._started:
            return None
        now = time.monotonic()
        limit = self.config.heartbeat_factor * self._heartbeat_s
        with self._cond:
            for i in range(self.spec.n):
                active = self._emcy_active[i]
                if active is not None:
                    return f"safety stop: {self._who(i)}: {emcy.describe(*active)}; torque off"
            for i in range(self.spec.n):
                silent = now - self._heartbeat_at[i]
                if silent > limit:
                    return (
                        f"safety stop: {self._who(i)} lost: no heartbeat for {silent:.2f} s "
                        f"(heartbeat time {self._heartbeat_s:.3f} s x "
                        f"{self.config.heartbeat_factor}); torque off"
                    )
                if self._nmt_state[i] != HEARTBEAT_OPERATIONAL:
                    return (
                        f"safety stop: {self._who(i)} left NMT OPERATIONAL (heartbeat state "
                        f"{self._nmt_state[i]}); torque off"
                    )
            for i in range(self.spec.n):
                if self._rx_seq[i] >= 0 and _safe_decode(self._statusword[i]) is State.FAULT:
                    return (
                        f"safety stop: {self._who(i)} in FAULT (statusword "
                        f"0x{int(self._statusword[i]):04X}); torque off"
                    )
                waited = now - self._late_since[i]  # NaN when not waiting
                if waited > self.config.max_position_age_s:
                    return (
                        f"safety stop: {self._who(i)} answered no SYNC for {waited:.2f} s "
                        f"({self._missed[i]} cycles); torque off"
                    )
        return None

    def _trip(self, reason: str) -> None:
        """Stop: torque off on every node, then record the reason. A thread that calls
        ``_check`` meanwhile waits for the torque off, so ``SafetyStop`` is only ever raised
        once the drives were told."""
        with self._trip_lock:
            if self._stop_reason is not None or self._tripping.is_set():
                return
            self._tripping.set()
        try:
            log.error("%s", reason)
            self._emergency_torque_off()
        finally:
            self._stop_reason = reason
            self._tripping.clear()

    def _check(self) -> None:
        """Raise ``SafetyStop`` if the arm was stopped (or should be now)."""
        if self._stop_reason is None and not self._tripping.is_set():
            reason = self._health()
            if reason is not None:
                self._trip(reason)
        deadline = time.monotonic() + self.config.state_timeout_s + 1.0
        while self._tripping.is_set() and time.monotonic() < deadline:
            time.sleep(0.001)  # another thread is turning torque off
        if self._stop_reason is not None:
            raise SafetyStop(self._stop_reason)

    @property
    def stop_reason(self) -> str | None:
        """Why the arm was stopped (None while running)."""
        return self._stop_reason

    @property
    def position_resolution(self) -> np.ndarray:
        """One position increment per joint, shape (n,), rad (2 pi / the drive's increments per
        revolution, read from 0x608F at connect; 0 before)."""
        if self.scaling is None:
            return np.zeros(self.spec.n)
        return math.tau / self.scaling.counts_per_rev

    @property
    def can_reconnect(self) -> bool:
        """Always: the bus is reopened from its spec, the drives configured again (they may
        still be enabled, holding their last target: the configuration leaves that alone)."""
        return True

    def _backend_counts(self) -> dict[str, float]:
        """Cycles, late cycles (a TPDO missed ``pdo_timeout_s``) and TPDOs missing in them."""
        return {f"can_{k}": v for k, v in self.stats.items()}

    # ---- I/O cycle -------------------------------------------------------------------------
    def _io(self) -> _IoGuard:
        return _IoGuard(self)

    def _cycle(self, send_rpdo: bool = True) -> None:
        """RPDO1 to every node (controlword + target), then a SYNC, then wait for the TPDOs.

        Raises:
            CanBusError: the adapter failed (unplugged, bus off, serial error).
        """
        import can

        self._check_preempted()
        with self._cond:
            self._seq += 1
            seq = self._seq
        sent_at = time.monotonic()
        try:
            if send_rpdo:
                for i, node in enumerate(self.nodes):
                    pdo = node.rpdo.map[1]
                    pdo[0x6040].raw = int(self._cw[i])
                    pdo[0x607A].raw = int(self._target[i])
                    pdo.transmit()
            self.network.sync.transmit()
        except (can.CanError, OSError) as exc:
            detail = " ".join(str(exc).split()) or type(exc).__name__
            raise CanLinkLost(f"CAN bus {self.bus_spec} failed: {detail}") from exc
        self.stats["cycles"] += 1
        with self._cond:
            self._cond.wait_for(
                lambda: bool(np.all(self._rx_seq >= seq)) or self._preempted(),
                self.config.pdo_timeout_s,
            )
            self._check_preempted()
            late = self._rx_seq < seq
            if late.any():
                self.stats["late_cycles"] += 1
                self.stats["missing_tpdos"] += int(late.sum())
            self._missed[late] += 1
            self._late_since[late & np.isnan(self._late_since)] = sent_at
        self._sync_since_read = True

    def _preempted(self) -> bool:
        return self._preempt.is_set() and self._preempt_by != threading.get_ident()

    def _check_preempted(self) -> None:
        if self._preempted():
            raise CyclePreemptedError(
                f"bus cycle on {self.bus_spec} given up: another thread is cutting torque"
            )

    def _first_positions(self) -> None:
        """SYNC until every node has sent a TPDO (or ``state_timeout_s`` passed)."""
        deadline = time.monotonic() + self.config.state_timeout_s
        while True:
            self._cycle(send_rpdo=False)
            with self._cond:
                never = [self._who(i) for i in np.flatnonzero(self._rx_seq < 0)]
            if not never:
                with self._cond:
                    self._missed[:] = 0
                    self._late_since[:] = np.nan
                return
            if time.monotonic() > deadline:
                raise CanNodeError(
                    f"no TPDO from {', '.join(never)} after NMT start and "
                    f"{self.config.state_timeout_s:.1f} s of SYNCs"
                )

    def _lost(self) -> set[int]:
        """Nodes that cannot confirm anything: heartbeat silent too long, or no TPDO for 3
        cycles (guess: one lost frame is normal, three in a row are not)."""
        now = time.monotonic()
        limit = self.config.heartbeat_factor * self._heartbeat_s
        with self._cond:
            silent = now - self._heartbeat_at > limit
            return set(np.flatnonzero(silent | (self._missed >= 3)).tolist())

    def _states(self) -> list[State | None]:
        with self._cond:
            return [_safe_decode(sw) for sw in self._statusword]

    def _states_are(self, state: State) -> np.ndarray:
        return np.array([s is state for s in self._states()])

    # ---- Arm hooks -------------------------------------------------------------------------
    def _read(self) -> JointState:
        self._check()
        try:
            with self._io():
                if not self._sync_since_read:
                    self._cycle(send_rpdo=False)
                self._sync_since_read = False
        except CyclePreemptedError:
            self._check()  # a safety stop preempted us: say so (SafetyStop)
            raise
        self._check()
        assert self.scaling is not None
        with self._cond:
            q = self.scaling.to_rad(self._counts)
            vel = self._velocity.copy()
            errors = np.array([a[0] if a else 0 for a in self._emcy_active], dtype=int)
        return JointState.from_positions(q, time.monotonic(), velocities=vel, errors=errors)

    def _send(self, positions: np.ndarray) -> None:
        self._check()
        assert self.scaling is not None
        counts = self.scaling.to_counts(positions)
        try:
            with self._io():
                self._target[:] = counts
                self._cycle(send_rpdo=True)
        except CyclePreemptedError:
            self._check()  # a safety stop preempted us: say so (SafetyStop)
            raise
        self._check()

    def _set_torque(self, enabled: bool) -> None:
        if enabled:
            self._check()
            self._drive_to(State.OPERATION_ENABLED)
        else:
            self._drive_to(State.SWITCHED_ON)

    def _drive_to(self, target: State) -> None:
        """Walk every node to ``target`` (OPERATION_ENABLED or SWITCHED_ON) through the
        controlword in RPDO1, one transition per cycle, holding the joints where they are.

        Torque off tells every node at once (lost ones too) in the first cycle, then waits
        for the confirmation of the nodes that can still give one; nodes below SWITCHED_ON or
        in FAULT already have their torque off and are left there.
        """
        deadline = time.monotonic() + self.config.state_timeout_s
        with self._io():
            with self._cond:
                self._target[:] = self._counts
            if target is State.SWITCHED_ON:
                enabling = (self._cw & 0x8F) == cia402.CW_ENABLE_OPERATION
                self._cw[enabling] = cia402.CW_DISABLE_OPERATION
                while True:
                    self._cycle(send_rpdo=True)
                    lost = self._lost()
                    todo = [
                        i
                        for i, st in enumerate(self._states())
                        if st is State.OPERATION_ENABLED and i not in lost
                    ]
                    if not todo:
                        return
                    if time.monotonic() > deadline:
                        names = ", ".join(self._who(i) for i in todo)
                        raise CanNodeError(f"torque off not confirmed by {names}")
            while True:
                states = self._states()
                todo = []
                for i, st in enumerate(states):
                    if st is target:
                        self._cw[i] = cia402.CW_ENABLE_OPERATION
                        continue
                    if st is State.FAULT:
                        raise CanNodeError(
                            f"{self._who(i)} is in FAULT: fix the cause, then reset_faults()"
                        )
                    todo.append(i)
                    cw = None if st is None else cia402.controlword_towards(st, target)
                    if cw is not None:
                        self._cw[i] = cw
                if not todo:
                    return
                if time.monotonic() > deadline:
                    names = ", ".join(
                        f"{self._who(i)} in {states[i].value if states[i] else 'an unknown state'}"
                        for i in todo
                    )
                    raise CanNodeError(f"timeout reaching {target.value!r}: {names}")
                self._cycle(send_rpdo=True)

    def _emergency_torque_off(self) -> None:
        # A signal handler runs in the main thread between bytecodes: if that thread is inside
        # our own bus I/O (holding locks of canopen/python-can), defer to the end of the cycle.
        if self._io_owner == threading.get_ident():
            self._pending_off = True
            self._torque = False
            return
        if self.network is None:
            self._torque = False
            return
        # From another thread (the signal watcher, the monitor): the cycle in progress gives
        # up at once instead of waiting for its TPDOs, then this thread takes the bus.
        self._preempt_by = threading.get_ident()
        self._preempt.set()
        with self._cond:
            self._cond.notify_all()
        try:
            super()._emergency_torque_off()
        finally:
            self._preempt.clear()
            self._preempt_by = None

    def reset_faults(self) -> None:
        """After a safety stop: fault reset on the drives in FAULT, clear the EMCY record and
        the stop (a lost node must be heard again first). Torque stays off."""
        self._require()
        with self._io():
            deadline = time.monotonic() + self.config.state_timeout_s
            while True:
                states = self._states()
                faulty = [i for i, s in enumerate(states) if s is State.FAULT]
                if not faulty:
                    break
                if time.monotonic() > deadline:
                    names = ", ".join(self._who(i) for i in faulty)
                    raise CanNodeError(f"fault reset did not clear {names}")
                for i in faulty:
                    cw = cia402.controlword_towards(
                        State.FAULT, State.SWITCH_ON_DISABLED, int(self._cw[i])
                    )
                    self._cw[i] = cw if cw is not None else 0
                self._cycle(send_rpdo=True)
            with self._cond:
                self._emcy_active = [None] * self.spec.n
                self._missed[:] = 0
                self._late_since[:] = np.nan
        self._stop_reason = None
        self._torque = False
        self._check()


class _IoGuard:
    """Holds the arm's I/O lock for one bus exchange; runs a deferred torque off after."""

    def __init__(self, arm: CanArm) -> None:
        self.arm = arm
        self._outer = False

    def __enter__(self) -> None:
        self.arm._io_lock.acquire()
        try:
            self._outer = self.arm._io_owner is None
            self.arm._io_owner = threading.get_ident()
        except BaseException:  # a signal between acquire and here: do not keep the lock
            self.arm._io_lock.release()
            raise

    def __exit__(self, *exc: object) -> None:
        arm = self.arm
        if self._outer:
            arm._io_owner = None
        arm._io_lock.release()
        if self._outer and arm._pending_off:
            arm._pending_off = False
            arm._emergency_torque_off()


def _safe_decode(statusword: int) -> State | None:
    try:
        return cia402.decode_statusword(int(statusword))
    except cia402.Cia402Error:
        return None


def make_can_arm(
    can: str,
    bitrate: int | None = DEFAULT_BITRATE,
    node_ids: Sequence[int] | None = None,
    **config: Any,
) -> CanArm:
    """A ``CanArm`` for the Ergo Jr from plain options (used by the rig factory)."""
    cfg = CanArmConfig(node_ids=tuple(node_ids) if node_ids else None, **config)
    return CanArm(can, bitrate=bitrate, config=cfg)
