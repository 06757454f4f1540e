"""One emulated CiA 402 servo drive (a CANopen node) on one of the twin's joints: its object
dictionary, its power state machine, its position in increments (``sim.canopen.drives`` puts
six of them on a bus and runs their SYNC cycle).

The node is a ``canopen.LocalNode`` built from ``robot/canopen/ergo_drive.eds``: the library's
SDO server answers configuration requests, its NMT slave produces the heartbeat and its EMCY
producer reports faults. This module adds what a servo drive does with them: the CiA 402
power state machine (``robot.canopen.cia402``) driven by the controlword 0x6040 (from an RPDO
or an SDO write), the mode of operation 0x6060, the software position limits 0x607D on its
target, faults (EMCY + FAULT, cleared by a fault reset), and its encoder: the drive's angle is
``robot.angles.raw_angle`` of the joint's, whole turns included (single-turn encoders read
0..2 pi at power on, multi-turn ones keep their count).
"""

from __future__ import annotations

import logging
import math
import time
from pathlib import Path
from typing import Any

import canopen
from canopen.sdo import SdoAbortedError

from robot.angles import TURN, joint_angle_in_turn, raw_angle
from robot.canopen import cia402, emcy
from robot.canopen.cia402 import State
from sim.canopen.guard import check_guard_write

log = logging.getLogger(__name__)

CSP = 8  # modes of operation 0x6060: cyclic synchronous position (CiA 402-2)
# SDO abort codes (CiA 301 table "SDO abort codes").
ABORT_VALUE_RANGE = 0x06090030
ABORT_DEVICE_STATE = 0x08000022
# Error register bits set while in fault (generic + device profile; see robot.canopen.emcy).
FAULT_REGISTER = emcy.FOLLOWING_ERROR_REGISTER
SUPPORTED_MODES = (CSP,)
# Quick stop option codes 0x605A after which a drive stays in QUICK STOP ACTIVE, holding its
# position (CiA 402-2: 5..8; 0..4 end in SWITCH ON DISABLED). The emulated drive's default is
# 6 (its EDS; CiA 402-2's is 2): a drive that stays powered in quick stop is the case a host
# must handle, so the emulator shows it.
QUICK_STOP_STAYS = (5, 6, 7, 8)
# The states in which the motor holds torque.
HOLDING = (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE)


class EmulatedDrive:
    """One CiA 402 node: the object dictionary, the state machine and one twin joint.

    Args:
        node_id: CANopen node id (1..127).
        joint: index of the twin joint it drives (0..5).
        eds: the drive's EDS file.
        direction: +1 or -1, how the drive is "mounted" (drive counts grow with the joint or
            against it).
        offset: joint angle at drive position 0, rad (``robot.canopen.units``' convention;
            the drive's angle at joint zero is ``-direction * offset``, any number of turns).
        single_turn: a single-turn absolute encoder (reads 0..2 pi at power on, then counts
            on) instead of a multi-turn one.
    """

    def __init__(
        self,
        node_id: int,
        joint: int,
        eds: Path,
        direction: float = 1.0,
        offset: float = 0.0,
        single_turn: bool = False,
    ) -> None:
        if not 1 <= node_id <= 127:
            raise ValueError(f"CANopen node id must be 1..127, got {node_id}")
        self.node_id = node_id
        self.joint = joint
        self.direction = float(direction)
        self.offset = float(offset)
        #: the drive's angle at joint zero, rad (``robot.angles``' offset), any number of turns
        self.zero_mark = -self.direction * self.offset
        #: a single-turn absolute encoder reads 0..2 pi at power on (``power_on``), then
        #: counts on; a multi-turn one keeps its count
        self.single_turn = single_turn
        self.turns = 0  # whole turns the encoder added at power on
        self.quick_stop_input = False  # the drive's own quick-stop input, active
        self.node = canopen.LocalNode(node_id, canopen.import_od(str(eds), node_id))
        self.state = State.NOT_READY_TO_SWITCH_ON
        self.controlword = 0
        self.error_code = 0
        self.demand = 0  # position demand, increments (the target the drive follows)
        self.actual = 0  # position actual, increments
        self.enabled_since: float | None = None
        # wall time (time.monotonic, system-wide) the drive last left OPERATION ENABLED, for
        # measuring how fast a host cuts torque
        self.disabled_at: float | None = None
        self.heartbeat_stopped = False
        self.muted = False  # sends no TPDO (on top of a stopped heartbeat: a dead node)
        self._rpdo_pending: list[Any] = []
        self._cpr: float | None = None
        self._mode: int | None = None
        self._sync_count = 0
        self.node.add_read_callback(self._on_read)
        self.node.add_write_callback(self._on_write)
        # Serial number: the node id, so that a scan tells the six drives apart.
        self.node.data_store.setdefault(0x1018, {})[4] = node_id.to_bytes(4, "little")

    # ---- object dictionary ---------------------------------------------------------------
    def od_int(self, index: int, subindex: int = 0) -> int:
        obj = self.node.object_dictionary[index]
        var = obj if isinstance(obj, canopen.objectdictionary.ODVariable) else obj[subindex]
        return int(var.decode_raw(self.node.get_data(index, subindex)))

    @property
    def counts_per_rev(self) -> float:
        """Increments per revolution from 0x608F (sub 1 / sub 2), cached."""
        if self._cpr is None:
            self._cpr = self.od_int(0x608F, 1) / max(1, self.od_int(0x608F, 2))
        return self._cpr

    @property
    def mode(self) -> int:
        """Modes of operation 0x6060, cached."""
        if self._mode is None:
            self._mode = self.od_int(0x6060)
        return self._mode

    def statusword(self) -> int:
        extra = cia402.SW_REMOTE
        if self.state is State.OPERATION_ENABLED and self.mode == CSP:
            extra |= cia402.SW_CSP_FOLLOWING
        return cia402.encode_statusword(self.state, extra)

    def _on_read(self, index: int, subindex: int, od: Any) -> int | None:
        """Live values of the dynamic objects (the rest comes from the data store/EDS)."""
        if index == 0x6041:
            return self.statusword()
        if index == 0x6064:
            return self.actual
        if index == 0x6061:
            return self.mode
        if index == 0x60F4:
            return self.actual - self.demand
        if index == 0x603F:
            return self.error_code
        if index == 0x1001:
            return FAULT_REGISTER if self.state is State.FAULT else 0
        return None

    def _on_write(self, index: int, subindex: int, od: Any, data: bytes) -> None:
        check_guard_write(index, data)
        if index == 0x608F and subindex in (1, 2):
            value = int.from_bytes(data[:4], "little")
            inc = value if subindex == 1 else self.od_int(0x608F, 1)
            revs = value if subindex == 2 else self.od_int(0x608F, 2)
            if inc <= 0 or revs <= 0:
                raise SdoAbortedError(ABORT_VALUE_RANGE)
            self._cpr = inc / revs
        if index == 0x6060:
            mode = int.from_bytes(data, "little", signed=True)
            if mode not in SUPPORTED_MODES and mode != 0:
                raise SdoAbortedError(ABORT_VALUE_RANGE)
            if self.state is State.OPERATION_ENABLED:
                raise SdoAbortedError(ABORT_DEVICE_STATE)
            self._mode = mode
        elif index == 0x6040:
            self.apply_controlword(int.from_bytes(data[:2], "little"))
        elif index == 0x607A and self.state is not State.QUICK_STOP_ACTIVE:  # it holds
            self.demand = self._limit(int.from_bytes(data[:4], "little", signed=True))

    def _limit(self, counts: int) -> int:
        """Clamp a target to the software position limits 0x607D."""
        lo, hi = self.od_int(0x607D, 1), self.od_int(0x607D, 2)
        return min(max(counts, lo), hi) if lo < hi else counts

    # ---- state machine ---------------------------------------------------------------------
    @property
    def holds_torque(self) -> bool:
        """Whether the motor holds torque: OPERATION ENABLED (following its demand) or QUICK
        STOP ACTIVE (holding where it stopped), in CSP."""
        return self.state in HOLDING and self.mode == CSP

    def apply_controlword(self, cw: int) -> None:
        """Run the CiA 402 state machine on a new controlword (its quick stop bit 2 active,
        i.e. 0, while the quick-stop input is: ``set_quick_stop_input``)."""
        effective = cw & ~cia402.CW_QUICK_STOP_BIT if self.quick_stop_input else cw
        before, holding = self.state, self.holds_torque
        self.state = cia402.next_state(self.state, effective, self.controlword)
        self.controlword = cw
        if before is State.FAULT and self.state is not State.FAULT:
            self.error_code = 0
            self.node.emcy.reset(0)  # EMCY 0x0000: error reset
        if self.state is State.QUICK_STOP_ACTIVE and before is not State.QUICK_STOP_ACTIVE:
            # the quick stop: no deceleration ramp emulated, the motor stops where it is; then
            # the quick stop option code 0x605A says whether it stays, holding (5..8), or goes
            # on to SWITCH ON DISABLED (0..4, transition 12, automatic) (CiA 402-2)
            self.demand = self.actual
            if self.od_int(0x605A) not in QUICK_STOP_STAYS:
                self.state = State.SWITCH_ON_DISABLED
        if self.state is State.OPERATION_ENABLED and before is not State.OPERATION_ENABLED:
            self.demand = self.actual  # CSP: take over where the joint is, no jump
            self.enabled_since = time.monotonic()
        elif self.state is not State.OPERATION_ENABLED:
            self.enabled_since = None
        if holding and not self.holds_torque:
            self.disabled_at = time.monotonic()

    def set_quick_stop_input(self, active: bool) -> None:
        """The drive's own quick-stop input (a switch wired to it): while active, every
        controlword counts with its quick stop bit active, so OPERATION ENABLED goes to QUICK
        STOP ACTIVE (transition 11) and nothing but "disable voltage" (transition 12) leaves
        it; released, the host's next controlword applies as sent."""
        self.quick_stop_input = active
        self.apply_controlword(self.controlword)

    def trip(self, code: int = emcy.FOLLOWING_ERROR, register: int = FAULT_REGISTER) -> None:
        """Fault (transition 13 then 14): FAULT state, error code 0x603F and an EMCY frame."""
        if self.state is State.FAULT:
            return
        self.state = cia402.next_state(cia402.fault(self.state), self.controlword)
        self.error_code = code
        self.enabled_since = None
        log.warning("drive %d: %s", self.node_id, emcy.describe(code, register))
        self.node.emcy.send(code, register)

    # ---- cyclic data -----------------------------------------------------------------------
    @property
    def operational(self) -> bool:
        return self.node.nmt.state == "OPERATIONAL"

    def load_pdo_config(self) -> None:
        """(Re)read the PDO communication and mapping objects from the local dictionary (the
        master wrote them by SDO) and subscribe the RPDOs."""
        self.node.rpdo.read(from_od=False)
        self.node.tpdo.read(from_od=False)
        for pdo in self.node.rpdo.map.values():
            if self._on_rpdo not in pdo.callbacks:
                pdo.add_callback(self._on_rpdo)

    def _on_rpdo(self, pdo: Any) -> None:
        if not self.operational:
            return
        if pdo.trans_type is not None and pdo.trans_type <= 240:
            self._rpdo_pending.append(pdo)  # synchronous: applied at the next SYNC
        else:
            self._apply_rpdo(pdo)

    def _apply_rpdo(self, pdo: Any) -> None:
        data = bytes(pdo.data)
        for var in pdo.map:
            if var.length and var.offset is not None:
                chunk = data[var.offset // 8 : (var.offset + var.length) // 8]
                if len(chunk) * 8 == var.length:
                    self.node.set_data(var.index, var.subindex, chunk)

    def apply_pending(self) -> None:
        """At SYNC: apply the synchronous RPDOs received since the previous SYNC."""
        pending, self._rpdo_pending = self._rpdo_pending, []
        for pdo in pending:
            self._apply_rpdo(pdo)

    def transmit_sync_tpdos(self) -> None:
        """At SYNC: transmit the synchronous TPDOs whose period (transmission type) is due."""
        self._sync_count += 1
        if self.muted or not self.operational:
            return
        for pdo in self.node.tpdo.map.values():
            tt = pdo.trans_type
            if not pdo.enabled or tt is None or tt > 240:
                continue
            if tt > 1 and self._sync_count % tt:
                continue
            for var in pdo.map:
                if var.length:
                    var.set_data(self.node.get_data(var.index, var.subindex))
            pdo.transmit()

    def joint_target(self, counts_per_rev: float) -> float:
        """The twin target for this joint, rad (the demand, in CSP while enabled): where the
        shaft goes, whole turns included (``robot.angles.joint_angle_in_turn``)."""
        drive = self.demand * math.tau / counts_per_rev - self.turns * TURN
        return float(joint_angle_in_turn(drive, self.zero_mark, self.direction))

    def to_counts(self, q: float, counts_per_rev: float) -> int:
        """The position actual of joint angle ``q`` (rad), increments."""
        drive = raw_angle(q, self.zero_mark, self.direction) + self.turns * TURN
        return round(float(drive) * counts_per_rev / math.tau)

    def power_on(self, q: float) -> None:
        """The encoder read at power on with the joint at ``q`` (rad): a single-turn encoder
        then reads 0..2 pi (the whole turns set so), a multi-turn one keeps its count."""
        if self.single_turn:
            self.turns = -math.floor(float(raw_angle(q, self.zero_mark, self.direction)) / TURN)
