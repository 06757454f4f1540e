"""Torque off reaches "not powered" from every powered CiA 402 state: OPERATION ENABLED, QUICK
STOP ACTIVE and SWITCHED ON (the power stage on in all three, CiA 402-2), read back by the
arm, and by the frames that are sent without reading back (the blind torque off, the
guardian's SLCAN lines). "Not powered" is SWITCH ON DISABLED, READY TO SWITCH ON (or FAULT).

A drive reaches QUICK STOP ACTIVE by the quick stop command (transition 11), as its own
quick-stop input or its reaction to a lost host (0x6007 = 3) gives it; the emulated drive then
stays there, holding its position (quick stop option code 0x605A = 6). It ignores "disable
operation" (0x07); "disable voltage" (0x00, transition 12) takes it to SWITCH ON DISABLED.
"""

from __future__ import annotations

import time
import uuid
from collections.abc import Iterator

import can
import pytest

from robot import SafetyStop
from robot.canopen.arm import CanArm, CanArmConfig
from robot.canopen.cia402 import CW_DISABLE_OPERATION, CW_QUICK_STOP, CW_TORQUE_OFF, State
from robot.canopen.config import ABORT_QUICK_STOP, EDS_PATH
from sim.canopen.drive import CSP, EmulatedDrive
from sim.canopen.drives import EmulatedDrives
from sim.twin import Twin

PERIOD_S = 0.025
HEARTBEAT_MS = 200
BOUND_S = 10.0  # against hangs
NOT_POWERED = {State.SWITCH_ON_DISABLED, State.READY_TO_SWITCH_ON}
# how a test puts node 3 in each powered state from OPERATION ENABLED: the controlword the
# drive receives (quick stop: transition 11; disable operation: transition 5)
INTO = {State.QUICK_STOP_ACTIVE: CW_QUICK_STOP, State.SWITCHED_ON: CW_DISABLE_OPERATION}


@pytest.fixture
def rig() -> Iterator[tuple[EmulatedDrives, str]]:
    channel = f"virtual:states-{uuid.uuid4().hex[:8]}"
    drives = EmulatedDrives(Twin(), channel, sync_step_s=PERIOD_S)
    drives.start()
    try:
        yield drives, channel
    finally:
        drives.stop()


def enabled_arm(drives: EmulatedDrives, channel: str, node_state: State) -> CanArm:
    """A connected arm with torque on, node 3 then put in ``node_state`` by the drive itself."""
    arm = CanArm(channel, config=CanArmConfig(heartbeat_ms=HEARTBEAT_MS))
    arm.connect()
    arm.set_torque(True)
    assert set(drives.states().values()) == {State.OPERATION_ENABLED}
    if node_state in INTO:
        with drives._lock:
            drives.drive(3).apply_controlword(INTO[node_state])
    assert drives.drive(3).state is node_state
    return arm


def powered(drives: EmulatedDrives) -> dict[int, State]:
    return {n: s for n, s in drives.states().items() if s not in NOT_POWERED}


def wait_unpowered(drives: EmulatedDrives) -> dict[int, State]:
    deadline = time.monotonic() + BOUND_S
    while powered(drives) and time.monotonic() < deadline:
        time.sleep(0.01)
    return powered(drives)


STATES = [State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE, State.SWITCHED_ON]


@pytest.mark.parametrize("node_state", STATES, ids=lambda s: s.name.lower())
def test_the_arms_torque_off_leaves_no_drive_powered_and_confirms_it(rig, node_state):
    """Was: torque off sent "disable operation" (0x07) and waited only for the nodes in
    OPERATION ENABLED: a node in QUICK STOP ACTIVE ignored it and was skipped, every node
    was left SWITCHED ON, and the torque off counted as confirmed."""
    drives, channel = rig
    arm = enabled_arm(drives, channel, node_state)
    try:
        arm.set_torque(False)
        assert powered(drives) == {}  # at once: the arm read it back
        assert arm.torque_off_report is None  # every drive confirmed it
        assert not arm.torque_enabled
    finally:
        arm.disconnect()
    assert powered(drives) == {}


@pytest.mark.parametrize("node_state", STATES, ids=lambda s: s.name.lower())
def test_the_blind_torque_off_leaves_no_drive_powered(rig, node_state):
    drives, channel = rig
    arm = enabled_arm(drives, channel, node_state)
    try:
        with arm.net.guard.hold():
            said = arm.net.blind_torque_off()
        assert "without confirmation" in said
        assert wait_unpowered(drives) == {}
    finally:
        arm.disconnect()


@pytest.mark.parametrize("node_state", STATES, ids=lambda s: s.name.lower())
def test_the_guardians_lines_leave_no_drive_powered(rig, node_state):
    """The bytes a guardian process writes to the SLCAN adapter, put on the bus as the adapter
    would put them."""
    drives, channel = rig
    arm = enabled_arm(drives, channel, node_state)
    try:
        lines = arm.net.torque_off_lines().decode().split("\r")[:-1]
        bus = can.Bus(interface="virtual", channel=channel.split(":", 1)[1])
        try:
            for line in lines:
                assert line[0] == "t"
                cob, size = int(line[1:4], 16), int(line[4])
                data = bytes.fromhex(line[5 : 5 + 2 * size])
                bus.send(can.Message(arbitration_id=cob, data=data, is_extended_id=False))
        finally:
            bus.shutdown()
        assert wait_unpowered(drives) == {}
    finally:
        arm.disconnect()


def test_a_drive_quick_stopped_by_its_input_stops_the_arm_and_torque_off_reaches_it(rig):
    """The drive's own quick-stop input pressed while the arm holds torque: the drive holds
    where it stopped in QUICK STOP ACTIVE, ignoring the host's targets; the arm stops in one
    line naming it, and its torque off takes that drive too out of its powered state (the
    input still pressed)."""
    drives, channel = rig
    arm = enabled_arm(drives, channel, State.OPERATION_ENABLED)
    try:
        drives.quick_stop(3)
        assert drives.drive(3).state is State.QUICK_STOP_ACTIVE and drives.drive(3).holds_torque
        with pytest.raises(SafetyStop, match=r"node 3 \(m3\) in QUICK STOP ACTIVE") as stop:
            deadline = time.monotonic() + BOUND_S
            while time.monotonic() < deadline:
                arm.command(arm.read().positions)
        assert "\n" not in str(stop.value) and "not confirmed" not in str(stop.value)
        assert powered(drives) == {} and arm.torque_off_report is None
    finally:
        arm.disconnect()
        drives.quick_stop(3, active=False)


def test_a_drive_that_quick_stops_when_it_loses_the_host_is_turned_off_by_the_arm(rig):
    """0x6007 = 3 (quick stop) and the host's heartbeat late: the drive goes to QUICK STOP
    ACTIVE and stays there (0x605A = 6); the host, alive, hears its EMCY 0x8130 and stops,
    its torque off confirmed by every drive."""
    drives, channel = rig
    config = CanArmConfig(heartbeat_ms=HEARTBEAT_MS, abort_option=ABORT_QUICK_STOP)
    arm = CanArm(channel, config=config)
    arm.connect()
    try:
        arm.set_torque(True)
        with drives._lock:  # node 3's watch of the host timed out
            drives.guard.react(drives.drive(3), config.master_id, 2.0)
        assert drives.drive(3).state is State.QUICK_STOP_ACTIVE
        with pytest.raises(SafetyStop, match="life guard or heartbeat error"):
            deadline = time.monotonic() + BOUND_S
            while time.monotonic() < deadline:
                arm.command(arm.read().positions)
        assert powered(drives) == {} and arm.torque_off_report is None
    finally:
        arm.disconnect()


@pytest.mark.parametrize(("option", "stays"), [(6, True), (5, True), (2, False), (0, False)])
def test_the_quick_stop_option_code_says_whether_a_drive_stays_in_quick_stop(option, stays):
    """CiA 402-2 0x605A: 5..8 stay in QUICK STOP ACTIVE holding the position, 0..4 go on to
    SWITCH ON DISABLED; either way the drive stops where it is, and "disable voltage" ends
    QUICK STOP ACTIVE (transition 12) while "disable operation" does not."""
    drive = EmulatedDrive(3, 2, EDS_PATH)
    drive.node.sdo[0x6060].raw = CSP
    drive.node.sdo[0x605A].raw = option
    for cw in (0x06, 0x07, 0x0F):
        drive.apply_controlword(cw)
    assert drive.state is State.OPERATION_ENABLED
    drive.actual, drive.demand = 1000, 1500  # moving towards 1500
    drive.apply_controlword(CW_QUICK_STOP)
    assert drive.demand == 1000  # stopped where it is
    expected = State.QUICK_STOP_ACTIVE if stays else State.SWITCH_ON_DISABLED
    assert drive.state is expected and drive.holds_torque is stays
    drive.node.sdo[0x607A].raw = 3000  # a target: one in quick stop holds where it stopped
    assert (drive.demand == 1000) is stays
    drive.apply_controlword(CW_DISABLE_OPERATION)
    assert drive.state is expected
    drive.apply_controlword(CW_TORQUE_OFF)
    assert drive.state is State.SWITCH_ON_DISABLED and not drive.holds_torque
