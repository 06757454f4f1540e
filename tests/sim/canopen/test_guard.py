"""The emulated drives guard the host: a CanArm configures each drive's heartbeat consumer
(0x1016) and abort connection option (0x6007) and produces its heartbeat; a drive that stops
hearing it leaves OPERATION ENABLED (torque off) with EMCY 0x8130, and one that refuses the
configuration stops the connect with one line naming the node and the object.

The deadlines are generous (the tests hold at load 8 on 2 cores): what is asserted is that
the drives stay enabled while the heartbeat runs, and are disabled once it stopped.
"""

from __future__ import annotations

import time
import uuid
from collections.abc import Iterator

import pytest
from canopen.sdo import SdoAbortedError

from robot import SafetyStop
from robot.canopen.arm import CanArm, CanArmConfig
from robot.canopen.cia402 import State
from robot.canopen.network import CanNodeError
from sim.canopen import guard
from sim.canopen.drives import EmulatedDrives
from sim.twin import Twin

PERIOD_S = 0.025
CONSUMER_MS = 600  # the drives' consumer time in these tests
BOUND_S = 10.0  # against hangs


@pytest.fixture
def rig() -> Iterator[tuple[EmulatedDrives, str]]:
    channel = f"virtual:guard-{uuid.uuid4().hex[:8]}"
    drives = EmulatedDrives(Twin(), channel, sync_step_s=PERIOD_S)
    drives.start()
    try:
        yield drives, channel
    finally:
        drives.stop()


def make_arm(can: str, **kw: object) -> CanArm:
    config = CanArmConfig(heartbeat_ms=200, master_heartbeat_ms=50, consumer_ms=CONSUMER_MS, **kw)
    return CanArm(can, config=config)


def states(drives: EmulatedDrives) -> set[State]:
    return set(drives.states().values())


def test_a_drive_drops_out_of_operation_enabled_when_the_hosts_heartbeat_stops(rig) -> None:
    drives, can = rig
    arm = make_arm(can)
    with arm:
        for d in drives.drives:
            assert d.node.sdo[0x1016][1].raw == 127 << 16 | CONSUMER_MS
            assert d.node.sdo[0x6007].raw == 2  # disable voltage
        arm.set_torque(True)
        # the heartbeat runs: still enabled after several consumer times
        end = time.monotonic() + 3 * CONSUMER_MS / 1000
        while time.monotonic() < end:
            arm.read()
            time.sleep(PERIOD_S)
        assert states(drives) == {State.OPERATION_ENABLED}
        assert drives.guard.reactions == []
        assert arm._host_heartbeat is not None
        stopped = time.monotonic()
        arm._host_heartbeat.stop()  # the host as it dies: its heartbeat ends, nothing else
        deadline = stopped + BOUND_S
        while states(drives) != {State.SWITCH_ON_DISABLED} and time.monotonic() < deadline:
            time.sleep(0.02)
        assert states(drives) == {State.SWITCH_ON_DISABLED}
        first = min(t for _, t in drives.guard.reactions)
        # not before the consumer time has passed since the host's last heartbeat
        assert first - drives.guard.heard_at[127] >= CONSUMER_MS / 1000
        assert {d.error_code for d in drives.drives} == {guard.HEARTBEAT_CONSUMER_ERROR}
        # the host, still alive, hears the EMCY: a safety stop that says why
        with pytest.raises(SafetyStop, match="life guard or heartbeat error"):
            end = time.monotonic() + BOUND_S
            while time.monotonic() < end:
                arm.read()
                time.sleep(PERIOD_S)


def test_a_drive_hearing_the_host_again_clears_its_error_and_can_be_enabled(rig) -> None:
    drives, can = rig
    with make_arm(can) as arm:
        arm._host_heartbeat.stop()
    deadline = time.monotonic() + BOUND_S
    while len(drives.guard.reactions) < 6 and time.monotonic() < deadline:
        time.sleep(0.02)
    assert {d.error_code for d in drives.drives} == {guard.HEARTBEAT_CONSUMER_ERROR}
    with make_arm(can) as arm:  # a new host: heard again, error reset, torque on
        arm.set_torque(True)
        assert states(drives) == {State.OPERATION_ENABLED}
        assert {d.error_code for d in drives.drives} == {0}


def test_hold_on_crash_turns_the_drives_watch_off(rig) -> None:
    drives, can = rig
    arm = make_arm(can)
    arm.on_crash = "hold"
    with arm:
        assert {d.node.sdo[0x1016][1].raw & 0xFFFF for d in drives.drives} == {0}  # time 0: off


def test_a_drive_refusing_its_abort_option_stops_the_connect_in_one_line(rig) -> None:
    _drives, can = rig
    with pytest.raises(CanNodeError) as info:
        make_arm(can, abort_option=7).connect()  # not an option the drive implements
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith("node 1 (m1) refused 0x6007:0 = 7")
    assert "abort connection option code" in message and "docs/canopen.md" in message


def test_a_drive_without_a_heartbeat_consumer_stops_the_connect_in_one_line(
    rig, monkeypatch
) -> None:
    _drives, can = rig

    def refuse(index: int, data: bytes) -> None:
        if index == 0x1016:
            raise SdoAbortedError(0x06010002)  # attempt to write a read-only object

    monkeypatch.setattr("sim.canopen.drive.check_guard_write", refuse)
    with pytest.raises(CanNodeError) as info:
        make_arm(can).connect()
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith("node 1 (m1) refused 0x1016:1 = ")
    assert "heartbeat consumer (host node 127, 600 ms)" in message


def test_time_with_frames_waiting_unread_is_not_the_hosts_silence(rig) -> None:
    """The emulator starved (the host's frames wait in the pty): no reaction until it reads."""
    drives, can = rig
    behind = [True]
    drives.host_backlog = lambda: behind[0]
    with make_arm(can) as arm:
        arm.set_torque(True)
        arm._host_heartbeat.stop()
        time.sleep(3 * CONSUMER_MS / 1000)
        assert states(drives) == {State.OPERATION_ENABLED} and drives.guard.reactions == []
        behind[0] = False  # caught up: the host is silent indeed
        deadline = time.monotonic() + BOUND_S
        while states(drives) != {State.SWITCH_ON_DISABLED} and time.monotonic() < deadline:
            time.sleep(0.02)
        assert states(drives) == {State.SWITCH_ON_DISABLED}
