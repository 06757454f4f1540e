"""``CanArm``: the ``robot.Arm`` interface on six CiA 402 servo drives over CANopen.

The network itself (the ``canopen`` library's nodes, SDO, PDO maps, NMT, what the notifier
thread hears, the SYNC cycle and its preemption) is ``robot.canopen.network.DriveNetwork``;
this module is the arm on top of it: configuration, units, the CiA 402 state machine for
torque, the health monitor. At connect:

1. every node answers an SDO read of its device type 0x1000 (low word 402: a drive);
2. units: increments per revolution from 0x608F (position encoder resolution), and the
   offsets moved by whole turns to the turn each drive's position actual 0x6064 is in
   (``units.JointScaling.anchored``, ``robot.angles``);
3. SDO configuration: mode of operation 0x6060 = 8 (cyclic synchronous position), software
   position limits 0x607D from the arm spec, producer heartbeat 0x1017, the drive's guard of
   the host (``robot.canopen.guard``: the host's heartbeat, which the drive consumes, 0x1016,
   and its reaction when it stops, 0x6007), optionally the following error window 0x6065;
   PDO mapping RPDO1 = controlword 0x6040 + target position 0x607A, TPDO1 = statusword
   0x6041 + position actual 0x6064, both synchronous;
4. NMT start (OPERATIONAL), then one SYNC to read the drives' states and positions.

Each command is one cycle: RPDO1 to every node, then a SYNC; the drives apply the targets at
the SYNC and answer with TPDO1. ``read`` returns the positions of the latest TPDOs (sending a
SYNC itself if no command did since the last read). Torque on walks the CiA 402 state
machine (shutdown -> switch on -> operation enabled) through the controlword in RPDO1; torque
off is "disable voltage" (0x00) to every node, which takes a drive out of each state whose
power stage is on (operation enabled, quick stop active, switched on: ``cia402.POWER_STAGE_ON``)
in one transition, and is confirmed only once each node reads back a state without it.

Safety (on top of the base class's clamping, watchdog and torque off on exit; the reasons are
``robot.canopen.health``'s):
- heartbeat consumer: a node silent for longer than 1.5 x its heartbeat time stops the arm;
- EMCY messages and drives seen in FAULT or QUICK STOP ACTIVE stop the arm, with the decoded
  error;
- a node that answers no SYNC for ``max_position_age_s`` stops the arm;
A stop turns torque off on every node at once (from a monitor thread) and makes the next
``read``/``command`` raise ``SafetyStop`` with a one-line reason; ``reset_faults()`` clears it.
A torque off from another thread (the monitor, the signal watcher of
``robot.signals.torque_off_on_signals``) preempts the cycle in progress, which gives up at once
instead of waiting out its TPDO timeout (``robot.bus_guard.BusGuard``).

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
from pathlib import Path

import numpy as np

from robot.arm import Arm, JointState, RecoveryPolicy
from robot.canopen import cia402, health
from robot.canopen.bus import DEFAULT_BITRATE, CanBusSpec, parse_can_spec
from robot.canopen.cia402 import State
from robot.canopen.config import EDS_PATH, PTY_SETTINGS, CanArmConfig, config_for
from robot.canopen.guard import HostHeartbeat, configure_drive_guard
from robot.canopen.network import (
    CanNodeError,
    CyclePreemptedError,
    DriveNetwork,
)
from robot.canopen.units import JointScaling
from robot.errors import BusError, SafetyStop
from robot.spec import ArmSpec, ergo_jr_spec
from robot.torque_guardian import EmergencyPayload, serial_path
from robot.watchdog import Watchdog

log = logging.getLogger(__name__)

# re-exported: the settings of a CanArm live in ``robot.canopen.config``
__all__ = ["EDS_PATH", "PTY_SETTINGS", "CanArm", "CanArmConfig", "config_for"]

CSP = 8  # modes of operation 0x6060: cyclic synchronous position (CiA 402-2)
DEVICE_PROFILE_402 = 402  # low word of 0x1000 for a drive (CiA 402-2)


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
        cfg = self.config
        if not 1 <= cfg.master_id <= 127 or cfg.master_id in self.node_ids:
            raise ValueError(
                f"master_id must be a node id in 1..127 that no drive has, got {cfg.master_id}"
            )
        hb_ms, consumer_ms = cfg.master_heartbeat_ms, cfg.consumer_ms
        if hb_ms < 1 or not 2 * hb_ms <= consumer_ms <= 0xFFFF:
            raise ValueError(
                f"consumer_ms must be at least twice master_heartbeat_ms and at most 65535 "
                f"(got {cfg.consumer_ms} and {cfg.master_heartbeat_ms})"
            )
        if not -0x8000 <= cfg.abort_option <= 0x7FFF:
            raise ValueError(f"abort_option is a 16-bit integer (0x6007), got {cfg.abort_option}")
        self._host_heartbeat: HostHeartbeat | None = None
        self.scaling: JointScaling | None = None
        self._heartbeat_s = self.config.heartbeat_ms / 1000.0
        self._wake = threading.Event()
        # The drives' network: SDO, PDO, NMT, the notifier's state, the SYNC cycle; one cycle
        # at a time, preempted by a torque off from another thread (its ``guard``).
        self.net = DriveNetwork(
            self.bus_spec, self.node_ids, self.spec.names, Path(self.config.eds),
            self.config.sdo_timeout_s, self.config.pdo_timeout_s, on_alarm=self._wake.set,
        )  # fmt: skip
        self._stop_reason: str | None = None
        self._trip_lock = threading.Lock()
        self._tripping = threading.Event()
        self._closing = threading.Event()
        self._monitor: threading.Thread | None = None
        self._asked_at: float | None = None  # when the health was last asked, monotonic s
        self._stalled_until = 0.0  # a host stall's silence excused until then, monotonic s
        #: how the last torque off went when some drive could not confirm it (None: every
        #: drive that can answer confirmed it): "not confirmed by ...: sent to ..."
        self.torque_off_report: str | None = None

    # ---- connect ---------------------------------------------------------------------------
    def _connect(self) -> None:
        net = self.net
        net.reset_state()
        self._stop_reason = None
        try:
            with net.guard.hold():
                net.open()
                self._host_heartbeat = HostHeartbeat(
                    net.network, self.config.master_id, self.config.master_heartbeat_ms / 1000
                ).start()
                self._configure()
                net.start(self._heartbeat_s, self.config.state_timeout_s)
            self._start_monitor()
            with net.guard.hold():
                net.first_positions(self.config.state_timeout_s)
            enabled = net.states_are(State.OPERATION_ENABLED)
            self._torque = bool(np.all(enabled))
            net.cw[:] = np.where(enabled, cia402.CW_ENABLE_OPERATION, 0)
            with net.cond:
                net.target[:] = net.counts
        except BaseException:
            self._stop_monitor()
            self._close_network()
            raise

    def _configure(self) -> None:
        """SDO configuration of every node (NMT pre-operational first: PDOs off)."""
        net = self.net
        net.pre_operational()
        cpr = np.zeros(self.spec.n)
        for i in range(self.spec.n):
            device_type = net.sdo_read(i, 0x1000)
            if device_type & 0xFFFF != DEVICE_PROFILE_402:
                raise CanNodeError(
                    f"{net.who(i)} is not a CiA 402 drive (device type 0x{device_type:08X})"
                )
            increments, revolutions = net.sdo_read(i, 0x608F, 1), net.sdo_read(i, 0x608F, 2)
            if increments <= 0 or revolutions <= 0:
                raise CanNodeError(
                    f"{net.who(i)} reports a position encoder resolution of "
                    f"{increments}/{revolutions} increments per revolution"
                )
            cpr[i] = increments / revolutions
        # the offsets in the turn each drive counts in now (robot.angles): a single-turn
        # encoder reads 0..2 pi at power on, a multi-turn one any turn
        here = np.array([net.sdo_read(i, 0x6064) for i in range(self.spec.n)], dtype=float)
        self.scaling = JointScaling(cpr, self._directions, self._offsets).anchored(here)
        net.velocity_units = (self.scaling.counts_per_rev, self._directions)
        lo, hi = self.scaling.limits_to_counts(self.spec.lower, self.spec.upper)
        for i in range(self.spec.n):
            if net.sdo_read(i, 0x6060) != CSP:  # a drive may refuse it while enabled
                net.sdo_write(i, 0x6060, 0, CSP)
            net.sdo_write(i, 0x607D, 1, int(lo[i]))
            net.sdo_write(i, 0x607D, 2, int(hi[i]))
            net.sdo_write(i, 0x1017, 0, self.config.heartbeat_ms)
            consumer = 0 if self.on_crash == "hold" else self.config.consumer_ms
            configure_drive_guard(net, i, self.config.master_id, consumer, self.config.abort_option)
            if self.config.following_error_window is not None:
                window = self.config.following_error_window * cpr[i] / (2 * np.pi)
                net.sdo_write(i, 0x6065, 0, round(window))
            net.map_pdos(i)

    def emergency_payload(self) -> EmergencyPayload | None:
        """On an SLCAN adapter (a serial port), the torque-off lines a guardian process writes
        to it (``DriveNetwork.torque_off_lines``, refreshed every cycle); None on other
        interfaces (socketcan, virtual)."""
        path = serial_path(self.bus_spec.channel.split("@", 1)[0])
        if self.bus_spec.interface != "slcan" or path is None:
            return None
        if self.net.emergency is None:
            self.net.emergency = EmergencyPayload(path)
        self.net.emergency.set(self.net.torque_off_lines())
        return self.net.emergency

    # ---- disconnect ------------------------------------------------------------------------
    def _disconnect(self) -> None:
        self._stop_monitor()
        self._close_network()

    def _close_network(self) -> None:
        """Stop the host's heartbeat (the drives then take their 0x6007 reaction after their
        consumer time: their torque is off already), then close the network."""
        if self._host_heartbeat is not None:
            self._host_heartbeat.stop()
            self._host_heartbeat = None
        self.net.close()

    def _stop_monitor(self) -> None:
        self._closing.set()
        self._wake.set()
        if self._monitor is not None and self._monitor is not threading.current_thread():
            self._monitor.join(timeout=2.0)
        self._monitor = None

    # ---- safety monitor --------------------------------------------------------------------
    def _start_monitor(self) -> None:
        self._closing.clear()
        self._asked_at, self._stalled_until = None, 0.0
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
        """A one-line reason to stop the arm, or None when every node is healthy
        (``robot.canopen.health``)."""
        cfg = self.config
        now = time.monotonic()
        last, self._asked_at = self._asked_at, now
        limit = cfg.heartbeat_factor * self._heartbeat_s
        if last is not None and now - last > health.HOST_STALL_FRACTION * limit:
            self._stalled_until = now + self._heartbeat_s  # the host's own stall (health.py)
        return health.reason_to_stop(
            self.net, self._heartbeat_s, cfg.heartbeat_factor, cfg.max_position_age_s,
            host_stalled=now < self._stalled_until,
        )  # fmt: skip

    def _trip(self, reason: str) -> None:
        """Stop: torque off on every node, then record the reason. A thread that calls
        ``_check`` meanwhile waits for the torque off, so ``SafetyStop`` is only ever raised
        once the drives were told."""
        with self._trip_lock:
            if self._stop_reason is not None or self._tripping.is_set():
                return
            self._tripping.set()
        try:
            # the reason reaches the user once, as the SafetyStop the next call raises (the
            # CLI's one ``ergo: error:`` line); the moment of the trip only with --verbose
            log.debug("tripped: %s", reason)
            self._emergency_torque_off()
            if self.torque_off_report is not None and reason.endswith("; torque off"):
                reason += f" {self.torque_off_report}"
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
        """Cycles, late cycles (a TPDO missed ``pdo_timeout_s``), TPDOs missing in them, and
        garbled lines dropped from an SLCAN adapter."""
        counts = {f"can_{k}": v for k, v in self.net.stats.items()}
        counts["can_garbled_lines"] = self.net.garbled_lines
        return counts

    def _torque_off_words(self) -> str:
        if self.torque_off_report is None:
            return "torque off confirmed by every drive that answers"
        return (
            f"torque off {self.torque_off_report}; a drive cut off from the host keeps its "
            f"last target unless its own heartbeat consumer stops it (docs/canopen.md)"
        )

    def _lost(self) -> set[int]:
        """Nodes that cannot confirm anything (``DriveNetwork.lost``)."""
        return self.net.lost(self.config.heartbeat_factor * self._heartbeat_s)

    # ---- Arm hooks -------------------------------------------------------------------------
    def _read(self) -> JointState:
        net = self.net
        self._check()
        try:
            with net.guard.hold():
                if not net.sync_since_read:
                    net.cycle(send_rpdo=False)
                net.sync_since_read = False
                # stamped with their SYNC, at which the drives sampled them (a read that follows
                # a command reads the command's SYNC, up to a control period before the read)
                stamp = net.sync_at
        except CyclePreemptedError:
            self._check()  # a safety stop preempted us: say so (SafetyStop)
            raise
        self._check()
        assert self.scaling is not None
        with net.cond:
            q = self.scaling.to_rad(net.counts)
            vel = net.velocity.copy()
            errors = np.array([a[0] if a else 0 for a in net.emcy_active], dtype=int)
        return JointState.from_positions(q, stamp, velocities=vel, errors=errors)

    def _send(self, positions: np.ndarray) -> None:
        net = self.net
        self._check()
        assert self.scaling is not None
        counts = self.scaling.to_counts(positions)
        try:
            with net.guard.hold():
                net.target[:] = counts
                net.cycle(send_rpdo=True)
        except CyclePreemptedError:
            self._check()  # a safety stop preempted us: say so (SafetyStop)
            raise
        self._check()

    def _set_torque(self, enabled: bool) -> None:
        if enabled:
            self._check()
            try:
                self._drive_to(State.OPERATION_ENABLED)
            except CyclePreemptedError:
                self._check()  # a safety stop preempted us: say so (SafetyStop)
                raise
            self.torque_off_report = None  # an earlier unconfirmed torque off is history
        else:
            self._torque_off()

    def _torque_off(self) -> None:
        """Power stage off on every node (``_cut_power``), confirmed by each node that can
        answer. Nodes that cannot (lost, or the link failed under the exchange) get the
        torque-off frames once more without confirmation (``DriveNetwork.blind_torque_off``), and
        ``torque_off_report`` says so; a failed exchange still raises (``CanNodeError``)."""
        net = self.net
        if net.network is None:  # closed under the arm (a failed reconnection): blind only
            said = self.torque_off_report is not None  # the stop said so already
            self.torque_off_report = f"not confirmed: {net.blind_torque_off()}"
            quiet = said or self.quiet_torque_off  # said by the stop, or by the exception
            log.log(
                logging.DEBUG if quiet else logging.WARNING, "torque off %s", self.torque_off_report
            )
            return
        before, self.torque_off_report = self.torque_off_report, None
        for attempt in range(2):
            try:
                with net.guard.hold():
                    silent = self._cut_power()
                break
            except CyclePreemptedError:
                # another thread is cutting torque (a safety stop, a signal): once it is done,
                # confirm it here (what a disconnect during a trip needs)
                if attempt or not net.guard.wait_unpreempted(self.config.state_timeout_s):
                    raise
            except BusError as exc:
                with net.guard.hold():
                    sent = net.blind_torque_off()
                self.torque_off_report = f"not confirmed ({exc}): {sent}"
                raise CanNodeError(f"torque off {self.torque_off_report}") from exc
        with net.guard.hold():
            if silent:
                names = ", ".join(net.who(i) for i in silent)
                self.torque_off_report = (
                    f"not confirmed by {names} (silent): {net.blind_torque_off()}"
                )
                # said once: the disconnect after a stop sends it again (to the nodes still
                # silent), without a second line
                quiet = before is not None or self.quiet_torque_off
                level = logging.DEBUG if quiet else logging.WARNING
                log.log(level, "torque off %s", self.torque_off_report)

    def _cut_power(self) -> list[int]:
        """Torque off: "disable voltage" (``cia402.CW_TORQUE_OFF``) to every node at once (lost
        ones too) in the first cycle, with the joints held where they are, then cycles until
        every node that can still answer reads back a state whose power stage is off
        (``cia402.torque_is_off``: from OPERATION ENABLED, QUICK STOP ACTIVE and SWITCHED ON
        alike). Returns the lost nodes last heard with their power stage on (torque off not
        confirmed).

        Raises:
            CanNodeError: a node that answers kept its power stage on for ``state_timeout_s``.
        """
        net = self.net
        deadline = time.monotonic() + self.config.state_timeout_s
        with net.guard.hold():
            with net.cond:
                net.target[:] = net.counts
            net.cw[:] = cia402.CW_TORQUE_OFF
            while True:
                net.cycle(send_rpdo=True, on_sent=self._torque_off_sent)
                lost = self._lost()
                on = [i for i, st in enumerate(net.states()) if not cia402.torque_is_off(st)]
                todo = [i for i in on if i not in lost]
                if not todo:
                    return [i for i in on if i in lost]
                if time.monotonic() > deadline:
                    raise CanNodeError(f"torque off not confirmed by {self._where(todo)}")

    def _where(self, nodes: list[int]) -> str:
        """``node 3 (m3) in quick stop active, ...``: the nodes and their last states."""
        states = self.net.states()
        return ", ".join(
            f"{self.net.who(i)} in {states[i].value if states[i] else 'an unknown state'}"
            for i in nodes
        )

    def _drive_to(self, target: State) -> None:
        """Walk every node to ``target`` (OPERATION_ENABLED) through the controlword in
        RPDO1, one transition per cycle, holding the joints where they are."""
        net = self.net
        deadline = time.monotonic() + self.config.state_timeout_s
        with net.guard.hold():
            with net.cond:
                net.target[:] = net.counts
            while True:
                states = net.states()
                todo = []
                for i, st in enumerate(states):
                    if st is target:
                        net.cw[i] = cia402.CW_ENABLE_OPERATION
                        continue
                    if st is State.FAULT:
                        raise CanNodeError(
                            f"{net.who(i)} is in FAULT: fix the cause, then reset_faults()"
                        )
                    todo.append(i)
                    cw = None if st is None else cia402.controlword_towards(st, target)
                    if cw is not None:
                        net.cw[i] = cw
                if not todo:
                    return
                if time.monotonic() > deadline:
                    raise CanNodeError(f"timeout reaching {target.value!r}: {self._where(todo)}")
                net.cycle(send_rpdo=True)

    def _emergency_torque_off(self) -> None:
        guard = self.net.guard
        # A signal handler runs in the main thread between bytecodes: if that thread is inside
        # our own bus I/O (holding locks of canopen/python-can), defer to the end of the cycle.
        if guard.owned_by_me:
            guard.defer(self._emergency_torque_off)
            self._torque = False
            return
        if self.net.network is None:
            # the network closed under a connected arm (a reconnection that failed): the drives
            # may still be enabled; tell them without a network
            if self._connected:
                with guard.preempt():
                    self.torque_off_report = f"not confirmed: {self.net.blind_torque_off()}"
                log.warning("torque off %s", self.torque_off_report)
            self._torque = False
            return
        # From another thread (the signal watcher, the monitor): the cycle in progress gives
        # up at once instead of waiting for its TPDOs, then this thread takes the bus.
        with guard.preempt():
            super()._emergency_torque_off()

    def reset_faults(self) -> None:
        """After a safety stop: fault reset on the drives in FAULT, clear the EMCY record and
        the stop (a lost node must be heard again first). Torque stays off."""
        net = self.net
        self._require()
        with net.guard.hold():
            deadline = time.monotonic() + self.config.state_timeout_s
            while True:
                states = net.states()
                faulty = [i for i, s in enumerate(states) if s is State.FAULT]
                if not faulty:
                    break
                if time.monotonic() > deadline:
                    names = ", ".join(net.who(i) for i in faulty)
                    raise CanNodeError(f"fault reset did not clear {names}")
                for i in faulty:
                    cw = cia402.controlword_towards(
                        State.FAULT, State.SWITCH_ON_DISABLED, int(net.cw[i])
                    )
                    net.cw[i] = cw if cw is not None else 0
                net.cycle(send_rpdo=True)
            with net.cond:
                net.emcy_active = [None] * self.spec.n
                net.missed[:] = 0
                net.late_since[:] = np.nan
        self._stop_reason = None
        self._torque = False
        self._check()
