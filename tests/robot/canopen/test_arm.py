"""CanArm against the six emulated CiA 402 drives on python-can's in-process ``virtual`` bus.

The twin advances by one control period at every SYNC (``sync_step_s``): a fake clock that
keeps the runs deterministic and fast. Nothing here asserts on timing; loops that wait for an
event are bounded only so that a bug cannot hang the suite.
"""

from __future__ import annotations

import signal
import threading
import time
import uuid
from collections.abc import Iterator

import numpy as np
import pytest

from explore.learner.dmp import Dmp, DmpConfig
from robot import SafetyStop, torque_off_on_signals
from robot.arm import RecoveryPolicy
from robot.canopen.arm import CanArm, CanArmConfig
from robot.canopen.cia402 import State
from robot.canopen.network import CanNodeError
from sim.canopen.drives import EmulatedDrives
from sim.twin import Twin

PERIOD_S = 0.025  # 40 Hz, the episode's control rate
# Heartbeat of the drives in these tests (ms): long enough that a loaded shared CI machine does
# not delay a heartbeat past 1.5 x this, short enough to notice a lost node quickly.
HEARTBEAT_MS = 200
DIRECTIONS = (1.0, -1.0, 1.0, 1.0, -1.0, 1.0)
OFFSETS = (0.0, 0.1, 0.0, -0.2, 0.0, 0.05)
# DMP joint ranges (rad) that keep the arm in free space above the arena: tracking is then
# the drives' and the twin's actuators', not contacts with the floor or the walls.
FREE_LOWER = (-0.6, -0.3, -0.5, -0.6, -0.5, -0.5)
FREE_UPPER = (0.6, 0.5, 0.5, 0.6, 0.5, 0.5)
BOUND_S = 10.0  # a bound against hangs, not an expectation


@pytest.fixture
def rig() -> Iterator[tuple[Twin, EmulatedDrives, str]]:
    """A twin and its drives (mounted with the directions/offsets above) on a fresh channel."""
    twin = Twin()
    channel = f"test-{uuid.uuid4().hex[:8]}"
    drives = EmulatedDrives(
        twin, f"virtual:{channel}", directions=DIRECTIONS, offsets=OFFSETS, sync_step_s=PERIOD_S
    )
    drives.start()
    try:
        yield twin, drives, f"virtual:{channel}"
    finally:
        drives.stop()


def make_arm(can: str, **kw: object) -> CanArm:
    cfg = CanArmConfig(directions=DIRECTIONS, offsets=OFFSETS, heartbeat_ms=HEARTBEAT_MS, **kw)
    return CanArm(can, config=cfg)


def enabled(drives: EmulatedDrives) -> list[int]:
    return [nid for nid, s in drives.states().items() if s is State.OPERATION_ENABLED]


def test_connect_configures_the_drives_by_sdo(rig) -> None:
    twin, drives, can = rig
    drives.drive(4).node.sdo[0x608F][1].raw = 4096  # this drive has a coarser encoder
    with make_arm(can) as arm:
        assert arm.scaling is not None
        assert arm.scaling.counts_per_rev.tolist() == [65536, 65536, 65536, 4096, 65536, 65536]
        assert np.allclose(arm.position_resolution, 2 * np.pi / arm.scaling.counts_per_rev)
        for d in drives.drives:
            sdo = d.node.sdo
            assert sdo[0x6060].raw == 8  # cyclic synchronous position
            lo, hi = sdo[0x607D][1].raw, sdo[0x607D][2].raw
            assert lo < 0 < hi
            assert sdo[0x1017].raw == HEARTBEAT_MS
            assert sdo[0x1600][1].raw == 0x60400010 and sdo[0x1600][2].raw == 0x607A0020
            assert sdo[0x1A00][1].raw == 0x60410010 and sdo[0x1A00][2].raw == 0x60640020
            assert d.node.nmt.state == "OPERATIONAL"
        # software limits in increments match the spec's limits (m2, direction -1, offset 0.1)
        j = arm.spec.joints[1]
        lo, hi = drives.drive(2).node.sdo[0x607D][1].raw, drives.drive(2).node.sdo[0x607D][2].raw
        expect = sorted(-(np.array([j.lower, j.upper]) - 0.1) * 65536 / (2 * np.pi))
        assert abs(lo - expect[0]) <= 1 and abs(hi - expect[1]) <= 1
        # positions read through the drives equal the twin's, in radians
        assert np.allclose(arm.read().positions, twin.joint_positions(), atol=1e-3)
        assert not arm.torque_enabled and enabled(drives) == []


def test_dmp_trajectory_is_followed(rig) -> None:
    twin, drives, can = rig
    theta = np.random.default_rng(3).uniform(-1, 1, 48)
    trajectory = Dmp(DmpConfig(lower=FREE_LOWER, upper=FREE_UPPER)).trajectory(theta)  # (40, 6)
    sent, measured = [], []
    old_ticks = 0
    with make_arm(can) as arm:
        arm.set_torque(True)
        assert enabled(drives) == [1, 2, 3, 4, 5, 6] and twin.torque_enabled()
        before = twin.joint_positions()
        for q in np.vstack([trajectory, np.repeat(trajectory[-1:], 40, axis=0)]):
            sent.append(arm.command(q))
            measured.append(arm.read().positions)
            now = twin.joint_positions()
            fresh = np.isclose(measured[-1], now, atol=1e-3)
            if not fresh.all():
                # a loaded machine: a drive's TPDO came after the cycle's timeout (counted),
                # and its position is then one cycle old (robot/canopen/arm.py), for a few
                # cycles more when that late TPDO is taken for the next SYNC's: never older
                assert arm.net.stats["late_cycles"] > 0
                assert np.isclose(measured[-1], before, atol=1e-3)[~fresh].all()
                old_ticks += 1
            before = now
    assert old_ticks < 40, f"{old_ticks} of 80 readings one cycle old"
    sent, measured = np.array(sent), np.array(measured)
    # the drives moved the twin where the commands went: settled at the end, close throughout
    # (SimArm on the same commands: 0.009 rad at the end, 0.004 rms holding, 0.09 max moving)
    assert np.abs(measured[-1] - sent[-1]).max() < 0.03
    assert np.sqrt(np.mean((measured[40:] - sent[40:]) ** 2)) < 0.02
    assert np.abs(measured[:40] - sent[:40]).max() < 0.3
    assert np.ptp(measured, axis=0).min() > 0.2  # every joint really moved
    # torque off on exit: operation disabled on every drive, the twin limp
    assert enabled(drives) == [] and not twin.torque_enabled()


def test_lost_frames_are_tolerated(rig) -> None:
    _twin, drives, can = rig
    drives.drop_rate = 0.05
    target = np.array([0.4, 0.3, -0.3, 0.2, 0.3, -0.2])
    with make_arm(can) as arm:
        arm.set_torque(True)
        for _ in range(60):
            arm.command(target)
        state = arm.read()
    assert drives.dropped > 0
    assert np.abs(state.positions - target).max() < 0.05


def test_heartbeat_loss_stops_the_arm(rig) -> None:
    _twin, drives, can = rig
    with make_arm(can) as arm:
        arm.set_torque(True)
        drives.stop_heartbeat(3)  # still answers PDOs: only the heartbeat tells
        deadline = time.monotonic() + BOUND_S
        with pytest.raises(SafetyStop) as info:
            while time.monotonic() < deadline:
                arm.command(arm.spec.rest)
        message = str(info.value)
        assert "node 3 (m3) lost: no heartbeat" in message and "torque off" in message
        assert "\n" not in message
        assert 3 not in enabled(drives) and enabled(drives) == []  # the others disabled too
        with pytest.raises(SafetyStop):
            arm.read()  # stays stopped


def test_node_that_stops_answering_sync_stops_the_arm(rig) -> None:
    _twin, drives, can = rig
    with make_arm(can) as arm:
        arm.set_torque(True)
        drives.drive(5).muted = True  # heartbeat on, but no more TPDOs
        deadline = time.monotonic() + BOUND_S
        with pytest.raises(SafetyStop, match=r"node 5 \(m5\) answered no SYNC for"):
            while time.monotonic() < deadline:
                arm.command(arm.spec.rest)
        assert enabled(drives) == []  # the mute node still hears the disable and obeys


def test_emcy_following_error_stops_the_arm_and_fault_reset_recovers(rig) -> None:
    _twin, drives, can = rig
    with make_arm(can) as arm:
        arm.set_torque(True)
        for k in range(10):
            arm.command(np.full(6, 0.01 * k))
        drives.following_error(2)
        deadline = time.monotonic() + BOUND_S
        with pytest.raises(SafetyStop) as info:
            while time.monotonic() < deadline:
                arm.command(np.full(6, 0.1))
        assert "node 2 (m2): EMCY 0x8611 following error (error register 0x21" in str(info.value)
        assert drives.states()[2] is State.FAULT and enabled(drives) == []
        with pytest.raises(CanNodeError, match="in FAULT"):
            arm._drive_to(State.OPERATION_ENABLED)
        arm.reset_faults()
        assert drives.states()[2] is State.SWITCH_ON_DISABLED
        arm.set_torque(True)
        assert enabled(drives) == [1, 2, 3, 4, 5, 6]
        arm.command(np.full(6, 0.1))


def test_drive_following_error_window(rig) -> None:
    """A window written at connect makes the drive itself fault when the joint lags."""
    _twin, _drives, can = rig
    with make_arm(can, following_error_window=0.02) as arm:
        arm.set_torque(True)
        deadline = time.monotonic() + BOUND_S
        with pytest.raises(SafetyStop, match="EMCY 0x8611 following error"):
            q = arm.read().positions
            while time.monotonic() < deadline:  # a fast move: the joints lag by > 0.02 rad
                q = q + 0.1
                arm.command(q)


def test_sigint_turns_torque_off_at_once(rig) -> None:
    twin, drives, can = rig
    with make_arm(can) as arm:
        arm.set_torque(True)
        timer = threading.Timer(0.2, signal.raise_signal, args=(signal.SIGINT,))
        with pytest.raises(KeyboardInterrupt), torque_off_on_signals(arm):
            timer.start()
            deadline = time.monotonic() + BOUND_S
            while time.monotonic() < deadline:
                arm.command(arm.spec.rest)  # the signal lands inside or between bus cycles
        timer.cancel()
        # still connected (before __exit__): the drives were disabled by the handler itself
        assert arm.is_connected and not arm.torque_enabled
        assert enabled(drives) == [] and not twin.torque_enabled()


def test_signal_inside_a_bus_cycle_is_deferred_to_its_end(rig) -> None:
    _twin, drives, can = rig
    with make_arm(can) as arm:
        arm.set_torque(True)
        with arm.net.guard.hold():
            arm._emergency_torque_off()  # what the handler does if it lands here
            assert enabled(drives) == [1, 2, 3, 4, 5, 6]  # not while we hold the bus
        assert enabled(drives) == []


def test_unknown_node_is_a_clear_error(rig) -> None:
    _twin, _drives, can = rig
    # the default SDO timeout (0.3 s): at 50 ms a loaded machine can also miss nodes 1-5
    arm = make_arm(can, node_ids=(1, 2, 3, 4, 5, 9))
    with pytest.raises(CanNodeError, match=r"node 9 \(m6\) does not answer SDO 0x1000") as info:
        arm.connect()
    assert "\n" not in str(info.value) and not arm.is_connected


def test_scan_lists_the_drives(rig, capsys) -> None:
    import argparse

    from robot.canopen.scan import scan_cli

    _twin, _drives, can = rig
    args = argparse.Namespace(can=can, bitrate=None, ids=[1, 2, 3, 4, 5, 6, 7], listen_s=0.3)
    assert scan_cli(args) == 0
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 7  # header + six drives
    assert "0x00020192" in out[3] and "CiA 402 drive" in out[3] and "PRE-OPERATIONAL" in out[3]
    assert out[3].split()[0] == "3" and "0x00000003" in out[3]  # serial number = node id


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
def test_adapter_failure_is_a_clear_one_line_stop_and_reconnect_works(rig) -> None:
    """Without reconnection attempts (tests/system/test_can_faults.py has the recovery itself)."""
    _twin, drives, can = rig
    arm = make_arm(can)
    arm.recovery = RecoveryPolicy(attempts=0)
    arm.connect()
    arm.net.network.bus.shutdown()  # the adapter goes away under the arm
    with pytest.raises(SafetyStop, match=f"link lost \\(CAN bus {can} failed") as info:
        arm.command(arm.spec.rest)
    assert "\n" not in str(info.value)
    arm.disconnect()  # never raises, even with the bus gone
    assert not arm.is_connected
    with make_arm(can) as again:  # a fresh connection to the same drives
        again.set_torque(True)
        assert enabled(drives) == [1, 2, 3, 4, 5, 6]


def test_bad_heartbeat_settings() -> None:
    with pytest.raises(ValueError, match="heartbeat_ms must be >= 1"):
        CanArm("virtual:x", config=CanArmConfig(heartbeat_ms=0))


def test_a_reading_is_stamped_with_the_sync_its_positions_were_sampled_at(rig) -> None:
    """The drives sample the positions of their TPDOs at the SYNC: a read just after a command
    returns the command's SYNC and its time, one after a read its own."""
    _, _, can = rig
    with make_arm(can) as arm:
        arm.set_torque(True)
        q = arm.read().positions
        before = time.monotonic()
        arm.command(q)
        sent = time.monotonic()
        time.sleep(0.05)
        state = arm.read()  # no SYNC of its own: the command's, sampled 50 ms ago
        assert before <= state.timestamp <= sent, (before, state.timestamp, sent)
        before = time.monotonic()
        state = arm.read()  # a SYNC of its own
        assert before <= state.timestamp <= time.monotonic()
