"""Six emulated CiA 402 servo drives (CANopen nodes 1..6) backed by the twin's joints.

Each drive is a ``sim.canopen.drive.EmulatedDrive``: a ``canopen.LocalNode`` built from
``robot/canopen/ergo_drive.eds`` (the library's SDO server answers configuration requests, its
NMT slave produces the heartbeat and its EMCY producer reports faults) with the CiA 402 power
state machine (``robot.canopen.cia402``), driven by the controlword 0x6040 (from an RPDO or an
SDO write), and its encoder. This module puts six on a bus and adds the cycle:

- cyclic synchronous position (mode 8): synchronous RPDOs received between two SYNCs are
  applied at the SYNC; the joint targets go to the twin; then every node transmits its
  synchronous TPDOs (statusword 0x6041, position actual 0x6064 with the default mapping);
- software position limits 0x607D, following error 0x60F4 against the window 0x6065;
- faults: EMCY + FAULT state, cleared by a fault reset (rising edge of controlword bit 7);
- the watch of the host: the heartbeat consumer 0x1016 and the abort connection option code
  0x6007 (``sim.canopen.guard``): a silent host leaves the drive limp;

Physics: either a ``sim.realtime.RealtimeLoop`` steps the twin in wall time (the server), or
``sync_step_s`` advances it by a fixed amount at every SYNC (tests: a fake clock that makes
the loop deterministic and as fast as the CPU allows). In real-time mode each SYNC exchanges
targets and positions with the twin at that moment (``Twin.catch_up`` first steps the physics
up to the wall time, however late the loop's thread runs), as a drive latches its targets and
samples its position at the SYNC; it waits at most ``SYNC_LOCK_WAIT_S`` for the twin's lock,
else the TPDOs carry the latest positions of a pump thread, which exchanges with the twin
between SYNCs (every 5 ms: for SDO reads and state changes between SYNCs).

Each joint has its torque while its drive holds it (OPERATION ENABLED, or QUICK STOP ACTIVE
holding where it stopped); a joint whose drive does not is limp (its target its current
position).

Fault injection (for tests and ``ergo twin serve``): a rate of lost PDO/SYNC frames (in both
directions; heartbeats and SDOs are not dropped), a node that stops its heartbeat (and,
muted, its TPDOs), a following-error fault (EMCY 0x8611) now or after some time in OPERATION
ENABLED, any other EMCY fault (e.g. 0x2310 over-current, an overload), an extra delay before
the TPDOs of every SYNC or of a fraction of them (late frames). Corrupted frames are not
emulated: on CAN the controllers' CRC rejects them and the sender retransmits (ISO 11898-1),
so a host only ever sees a frame late or, if the bus gives up, not at all (a drop).
"""

from __future__ import annotations

import logging
import random
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from robot.canopen import cia402, emcy
from robot.canopen.bus import open_bus
from robot.canopen.cia402 import State
from robot.canopen.config import EDS_PATH
from sim.canopen.drive import FAULT_REGISTER, EmulatedDrive
from sim.canopen.faulty import SYNC_COB_ID, FaultyNetwork
from sim.canopen.guard import HostGuard
from sim.twin import Twin

log = logging.getLogger(__name__)

NODE_IDS = (1, 2, 3, 4, 5, 6)
# 0x6065 value meaning "following error monitoring off" (CiA 402-2).
WINDOW_OFF = 0xFFFFFFFF
NMT_RESET_NODE, NMT_RESET_COMM = 0x81, 0x82
NMT_PRE_OPERATIONAL = 0x80
# Real-time mode: longest interval between two exchanges with the twin, s (guess: a fifth of
# the 40 Hz control period, so positions are at most this old when the twin's lock is free).
PUMP_PERIOD_S = 0.005
# Real-time mode: the longest a SYNC waits for the twin's lock before it sends the pump's
# latest positions instead, s (guess: a fifth of the 40 Hz control period; the lock is held
# for a physics catch-up, about 6 ms per simulated s, or a scene copy for a render).
SYNC_LOCK_WAIT_S = 0.005


class EmulatedDrives:
    """The six drives on one CAN bus, backed by ``twin``.

    Args:
        twin: the twin whose joints the drives move.
        bus: an open python-can bus, or an ``INTERFACE:CHANNEL`` spec (``virtual:NAME`` in
            tests; the server bridges a virtual channel to its pty).
        node_ids: CANopen ids of the drives of joints m1..m6.
        directions, offsets: per joint, see ``EmulatedDrive``.
        sync_step_s: advance the twin by this much at each SYNC (None: a RealtimeLoop does).
        drop_rate: fraction of PDO/SYNC frames lost, each way.
        tpdo_delay_s: extra delay before the TPDOs of a SYNC, s.
        late_rate: fraction of SYNCs whose TPDOs get that delay (1: every SYNC).
        seed: seed of the loss draws.
        eds: the drives' EDS.
        single_turn: single-turn absolute encoders (each reads 0..2 pi at power on, then
            counts on) instead of multi-turn ones (the count the offsets give, any turn).
        heartbeats: who produces the nodes' heartbeats (``HeartbeatProducer.task``; None:
            python-can's periodic tasks on ``bus``).
    """

    def __init__(
        self,
        twin: Twin,
        bus: Any,
        node_ids: Sequence[int] = NODE_IDS,
        directions: Sequence[float] | None = None,
        offsets: Sequence[float] | None = None,
        sync_step_s: float | None = None,
        drop_rate: float = 0.0,
        tpdo_delay_s: float = 0.0,
        late_rate: float = 1.0,
        seed: int = 0,
        eds: Path = EDS_PATH,
        single_turn: bool = False,
        heartbeats: Callable[[int, bytes, float], Any] | None = None,
    ) -> None:
        if len(node_ids) != 6 or len(set(node_ids)) != 6:
            raise ValueError(f"need six distinct node ids, got {list(node_ids)}")
        if not 0.0 <= drop_rate < 1.0:
            raise ValueError(f"drop rate must be in [0, 1), got {drop_rate}")
        directions = [1.0] * 6 if directions is None else list(directions)
        offsets = [0.0] * 6 if offsets is None else list(offsets)
        self.twin = twin
        if not 0.0 <= late_rate <= 1.0:
            raise ValueError(f"late rate must be in [0, 1], got {late_rate}")
        self.sync_step_s = sync_step_s
        self.tpdo_delay_s = tpdo_delay_s
        self.late_rate = late_rate
        self.late_syncs = 0  # SYNCs whose TPDOs were delayed
        self._late_rng = random.Random(seed + 1)
        self.drives = [
            EmulatedDrive(nid, j, eds, directions[j], offsets[j], single_turn)
            for j, nid in enumerate(node_ids)
        ]
        self._by_id = {d.node_id: d for d in self.drives}
        self._owns_bus = isinstance(bus, str)
        self._bus = open_bus(bus) if isinstance(bus, str) else bus
        self.network = FaultyNetwork(self._bus, drop_rate, seed)
        self.network.heartbeats = heartbeats
        self._lock = threading.RLock()
        self._scheduled_faults: dict[int, float] = {}
        self.syncs = 0
        self._started = False
        self._q = np.zeros(6)  # latest joint positions read from the twin, rad
        self.stale_syncs = 0  # real-time SYNCs answered with the pump's positions (lock busy)
        self._pump_wake = threading.Event()
        self._pump_stop = threading.Event()
        self._pump_thread: threading.Thread | None = None
        #: whether frames from the host wait unread before this bus (the pty bridge's, set by
        #: the server), for the watch of the host
        self.host_backlog: Callable[[], bool] = lambda: False
        self.guard = HostGuard(self.drives, self._lock, self._backlog)  # the watch of the host

    # ---- lifecycle -------------------------------------------------------------------------
    def start(self) -> None:
        """Connect, boot every node (boot-up message, PRE-OPERATIONAL, heartbeat on)."""
        if self._started:
            return
        for d in self.drives:
            self.network.add_node(d.node)
        self.network.subscribe(SYNC_COB_ID, self._on_sync)
        self.network.subscribe(0x000, self._on_nmt)
        for cob_id, callback in self.guard.subscriptions():
            self.network.subscribe(cob_id, callback)
        self.network.connect()
        with self.twin.lock:
            q = self.twin.joint_positions()
        with self._lock:
            self._set_actuals(q)
        for d in self.drives:
            self._boot(d)
        if not self.sync_step_s:
            self._pump_stop.clear()
            self._pump_thread = threading.Thread(target=self._pump, name="drives-pump", daemon=True)
            self._pump_thread.start()
        self.guard.start()
        self._started = True

    def stop(self) -> None:
        """Stop heartbeats and the network; closes the bus if this object opened it."""
        if not self._started:
            return
        self._started = False
        if not self.sync_step_s:
            log.info(
                "emulated drives: %d SYNCs, %d of them answered with the pump's positions (the "
                "twin's lock busy for %.0f ms); the host's heartbeat silent for at most %.2f s "
                "while watched, %d reaction(s) to its loss",
                self.syncs,
                self.stale_syncs,
                SYNC_LOCK_WAIT_S * 1e3,
                self.guard.longest_silence_s,
                len(self.guard.reactions),
            )
        self.guard.stop()
        self._pump_stop.set()
        self._pump_wake.set()
        if self._pump_thread is not None:
            self._pump_thread.join(timeout=2.0)
            self._pump_thread = None
        for d in self.drives:
            d.node.nmt.stop_heartbeat()
        if self._owns_bus:
            self.network.disconnect()
        else:
            if self.network.notifier is not None:
                self.network.notifier.stop(self.network.NOTIFIER_SHUTDOWN_TIMEOUT)
            self.network.bus = None

    def _backlog(self) -> bool:
        queue = getattr(self._bus, "queue", None)  # python-can's virtual bus
        return bool(self.host_backlog() or (queue is not None and queue.qsize()))

    def __enter__(self) -> EmulatedDrives:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _boot(self, d: EmulatedDrive) -> None:
        d.power_on(float(self._q[d.joint]))
        d.actual = d.to_counts(float(self._q[d.joint]), d.counts_per_rev)
        d.demand = d.actual
        d.state = State.NOT_READY_TO_SWITCH_ON
        d.state = cia402.next_state(d.state, 0)  # self test done: switch on disabled
        d.controlword = 0
        d.node.nmt.send_command(NMT_RESET_NODE)  # state 0: sends the boot-up message
        d.node.nmt.send_command(NMT_PRE_OPERATIONAL)  # starts the heartbeat (0x1017)
        if d.heartbeat_stopped:
            d.node.nmt.stop_heartbeat()

    def _on_nmt(self, can_id: int, data: bytearray, timestamp: float) -> None:
        """After the library's NMT slave handled a command: reboot on reset, load the PDO
        configuration when entering OPERATIONAL."""
        if len(data) < 2:
            return
        cmd, target = data[0], data[1]
        with self._lock:
            for d in self.drives:
                if target not in (0, d.node_id):
                    continue
                if cmd in (NMT_RESET_NODE, NMT_RESET_COMM):
                    self._boot(d)
                elif d.operational:
                    d.load_pdo_config()
                if d.heartbeat_stopped:
                    d.node.nmt.stop_heartbeat()

    # ---- the cycle -------------------------------------------------------------------------
    def _plan(self) -> tuple[np.ndarray, np.ndarray]:
        """Which joints are driven (their drive holds torque: OPERATION ENABLED or QUICK STOP
        ACTIVE, in CSP) and their targets, shape (6,) each (bool, rad). Call under
        ``self._lock``."""
        enabled = np.zeros(6, dtype=bool)
        targets = np.zeros(6)
        for d in self.drives:
            enabled[d.joint] = d.holds_torque
            targets[d.joint] = d.joint_target(d.counts_per_rev)
        return enabled, targets

    def _twin_io(self, plan: tuple[np.ndarray, np.ndarray], step_s: float | None) -> np.ndarray:
        """Under the twin's lock: set the targets (joints not driven hold where they are) and
        the torque, step if asked; returns the joint positions, shape (6,), rad."""
        enabled, targets = plan
        with self.twin.lock:
            self.twin.catch_up()  # the physics at the wall time (a no-op without a real-time loop)
            q = self.twin.joint_positions_now()
            self.twin.set_targets(np.where(enabled, targets, q))
            if not np.array_equal(self.twin.torque_mask(), enabled):
                self.twin.set_joint_torque(enabled)
            if step_s:
                self.twin.step(step_s)
                q = self.twin.joint_positions()
        return q

    def _set_actuals(self, q: np.ndarray) -> None:
        """Position actual of every drive from joint positions (rad). Under ``self._lock``."""
        self._q = q
        for d in self.drives:
            d.actual = d.to_counts(float(q[d.joint]), d.counts_per_rev)

    def _pump(self) -> None:
        """Real-time mode: exchange targets and positions with the twin between SYNCs, at least
        every ``PUMP_PERIOD_S`` (and when a SYNC found the twin's lock busy). It may wait for
        the twin's lock, and takes it before the drives' lock, so that a SYNC never waits on
        the drives' lock while the pump waits for a render: the SYNC handler waits at most
        ``SYNC_LOCK_WAIT_S`` (for the twin's lock). The whole exchange is under both locks, so
        that a plan made before a SYNC never overwrites the targets or positions of that SYNC.
        (No deadlock: the only other taker of both, the SYNC handler, takes the twin's lock
        with a timeout.)"""
        while not self._pump_stop.is_set():
            self._pump_wake.wait(PUMP_PERIOD_S)
            self._pump_wake.clear()
            with self.twin.lock, self._lock:
                self._set_actuals(self._twin_io(self._plan(), None))

    def _exchange_at_sync(self) -> np.ndarray:
        """Real-time mode, at a SYNC (under ``self._lock``): the targets to the twin and its
        positions at this moment (the physics caught up to the wall time), as a drive latches
        its targets and samples its position at the SYNC. If the twin's lock is not free within
        ``SYNC_LOCK_WAIT_S``, the pump's latest positions instead (counted in ``stale_syncs``;
        the pump is woken to hand the targets over)."""
        if not self.twin.lock.acquire(timeout=SYNC_LOCK_WAIT_S):
            self.stale_syncs += 1
            self._pump_wake.set()
            return self._q
        try:
            return self._twin_io(self._plan(), None)
        finally:
            self.twin.lock.release()

    def _on_sync(self, can_id: int, data: bytearray, timestamp: float) -> None:
        try:
            self.cycle()
        except Exception:  # never kill the notifier thread
            log.exception("emulated drives: SYNC handling failed")

    def cycle(self) -> None:
        """One SYNC: apply the RPDOs, exchange with the twin (stepping it by ``sync_step_s``;
        in real-time mode the pump thread does it and the positions are its latest), check
        following errors, then send the TPDOs."""
        with self._lock:
            self.syncs += 1
            for d in self.drives:
                d.apply_pending()
            if self.sync_step_s:
                self._set_actuals(self._twin_io(self._plan(), self.sync_step_s))
            else:
                self._set_actuals(self._exchange_at_sync())
            now = time.monotonic()
            for d in self.drives:
                self._check_faults(d, now)
        if self.tpdo_delay_s > 0 and (
            self.late_rate >= 1.0 or self._late_rng.random() < self.late_rate
        ):
            self.late_syncs += 1
            time.sleep(self.tpdo_delay_s)
        with self._lock:
            for d in self.drives:
                d.transmit_sync_tpdos()

    def _check_faults(self, d: EmulatedDrive, now: float) -> None:
        if d.state is not State.OPERATION_ENABLED:
            return
        after = self._scheduled_faults.get(d.node_id)
        if after is not None and d.enabled_since is not None and now - d.enabled_since >= after:
            del self._scheduled_faults[d.node_id]
            d.trip()
            return
        window = d.od_int(0x6065)
        if window != WINDOW_OFF and abs(d.actual - d.demand) > window:
            d.trip()

    # ---- queries and fault injection -------------------------------------------------------
    def drive(self, node_id: int) -> EmulatedDrive:
        if node_id not in self._by_id:
            raise KeyError(f"no emulated drive with node id {node_id}")
        return self._by_id[node_id]

    def states(self) -> dict[int, State]:
        """CiA 402 state of every drive by node id."""
        return {d.node_id: d.state for d in self.drives}

    @property
    def drop_rate(self) -> float:
        return self.network.drop_rate

    @drop_rate.setter
    def drop_rate(self, rate: float) -> None:
        if not 0.0 <= rate < 1.0:
            raise ValueError(f"drop rate must be in [0, 1), got {rate}")
        self.network.drop_rate = rate

    @property
    def dropped(self) -> int:
        """Frames lost so far by injection."""
        return self.network.dropped

    def stop_heartbeat(self, node_id: int, mute: bool = False) -> None:
        """The node stops producing its heartbeat (and, with ``mute``, its TPDOs: dead)."""
        d = self.drive(node_id)
        d.heartbeat_stopped = True
        d.muted = mute
        d.node.nmt.stop_heartbeat()

    def fault(self, node_id: int, code: int, register: int = FAULT_REGISTER) -> None:
        """Trip any fault on the node now: FAULT state and an EMCY with ``code``, e.g.
        0x2310 continuous over-current (an overload) or 0x4310 excess temperature of the
        drive (CiA 301 / CiA 402 error codes, see ``robot.canopen.emcy``)."""
        with self._lock:
            self.drive(node_id).trip(code, register)

    def quick_stop(self, node_id: int, active: bool = True) -> None:
        """The node's own quick-stop input, pressed (``active``) or released
        (``EmulatedDrive.set_quick_stop_input``)."""
        with self._lock:
            self.drive(node_id).set_quick_stop_input(active)

    def following_error(self, node_id: int) -> None:
        """Trip a following-error fault on the node now (EMCY 0x8611, FAULT)."""
        with self._lock:
            self.drive(node_id).trip(emcy.FOLLOWING_ERROR, FAULT_REGISTER)

    def schedule_following_error(self, node_id: int, after_s: float) -> None:
        """Trip a following-error fault once the node has been OPERATION ENABLED for
        ``after_s`` seconds of wall time (checked at each SYNC)."""
        self.drive(node_id)
        self._scheduled_faults[node_id] = after_s
