"""Faults on the CANopen bus, through ``CanArm`` and the six emulated CiA 402 drives on
python-can's ``virtual`` bus (the twin steps one control period per SYNC: deterministic and
fast). Lost frames, a silent heartbeat, a mute node and a following error are in
tests/robot/canopen/test_arm.py; here: late TPDOs, an overload and an overheat EMCY, the adapter
lost and back (recovered in place: on the virtual bus, and an SLCAN adapter's pty closed and
reopened behind a stable link), and lost for good (safe stop).

Corrupted frames are not emulated: a CAN controller's CRC rejects them and the sender
retransmits (ISO 11898-1), so the host sees them late or, at worst, lost: the cases below.
Nothing here asserts on durations; waits are bounded only against hangs.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
import uuid
from collections.abc import Iterator

import numpy as np
import pytest

from robot.arm import RecoveryPolicy
from robot.canopen.arm import CanArm, CanArmConfig
from robot.canopen.cia402 import State
from robot.errors import SafetyStop
from sim.canopen.drives import EmulatedDrives
from sim.twin import Twin

PERIOD_S = 0.025  # 40 Hz, the episode's control rate
# the drives' heartbeat, ms, on both adapters: 200 (x 1.5 = 0.3 s) was missed at load 13 on
# 2 cores (0.41 s), and the pty rigs' 500 at load 10 (0.79 s against 0.75 s), before any
# fault was injected ("no heartbeat"); no test here waits for a heartbeat loss
HEARTBEAT_MS = 1000
# SDO answer timeout at connect, s: the emulated drives answer from their own threads, which
# wait for a CPU at load 10 on 2 cores (0.3 s, canopen's default, was missed there:
# "does not answer SDO 0x1000"; a real drive answers within milliseconds)
SDO_TIMEOUT_S = 2.0
BOUND_S = 10.0  # a bound against hangs, not an expectation
TARGET = np.array([0.3, 0.2, -0.3, 0.2, 0.2, -0.2])


@pytest.fixture
def rig() -> Iterator[tuple[Twin, EmulatedDrives, str]]:
    twin = Twin()
    channel = f"rel-{uuid.uuid4().hex[:8]}"
    drives = EmulatedDrives(twin, f"virtual:{channel}", sync_step_s=PERIOD_S)
    drives.start()
    try:
        yield twin, drives, f"virtual:{channel}"
    finally:
        drives.stop()
        twin.close()


def make_arm(can: str, recovery: RecoveryPolicy | None = None, **kw: object) -> CanArm:
    kw.setdefault("sdo_timeout_s", SDO_TIMEOUT_S)
    return CanArm(can, config=CanArmConfig(heartbeat_ms=HEARTBEAT_MS, **kw), recovery=recovery)


def enabled(drives: EmulatedDrives) -> list[int]:
    return [nid for nid, s in drives.states().items() if s is State.OPERATION_ENABLED]


def test_late_tpdos_are_counted_and_the_arm_goes_on(rig) -> None:
    _twin, drives, can = rig
    drives.tpdo_delay_s, drives.late_rate = 0.03, 0.3  # later than the 20 ms PDO timeout
    with make_arm(can, pdo_timeout_s=0.02) as arm:
        arm.set_torque(True)
        for _ in range(60):
            arm.command(TARGET)
            arm.read()
        counts = arm.fault_counts()
        state = arm.read()
    assert drives.late_syncs > 0
    assert counts["can_late_cycles"] > 0 and counts["can_missing_tpdos"] > 0, counts
    assert np.abs(state.positions - TARGET).max() < 0.05  # positions a cycle old at worst


@pytest.mark.parametrize(
    ("code", "words"),
    [(0x2310, "continuous over-current"), (0x4310, "excess temperature of the drive")],
)
def test_an_overload_or_overheat_emcy_stops_the_arm_with_torque_off(
    rig, code, words, caplog
) -> None:
    _twin, drives, can = rig
    caplog.set_level(logging.INFO, logger="robot")  # what the CLI shows
    with make_arm(can) as arm:
        arm.set_torque(True)
        for _ in range(5):
            arm.command(TARGET)
        drives.fault(4, code)
        deadline = time.monotonic() + BOUND_S
        with pytest.raises(SafetyStop) as info:
            while time.monotonic() < deadline:
                arm.command(TARGET)
        message = str(info.value)
        assert f"node 4 (m4): EMCY 0x{code:04X} {words}" in message and "torque off" in message
        assert "\n" not in message
        assert enabled(drives) == []  # every drive, not only the faulty one
        assert arm.fault_counts()["reconnects"] == 0  # a fault is a stop, never a reconnect
    # the reason is said once, by the SafetyStop (the CLI's one error line), not logged too
    repeated = [
        r.getMessage()
        for r in caplog.records
        if r.name.startswith("robot")
        and r.levelno >= logging.INFO
        and f"0x{code:04X}" in r.getMessage()
    ]
    assert repeated == [], repeated


# python-can's notifier thread dies with the adapter (a closed bus raises in ``recv``), as it
# does when a real adapter is pulled out: expected here, not a bug of the test.
DEAD_NOTIFIER = pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")


@DEAD_NOTIFIER
def test_a_lost_adapter_is_reopened_and_the_arm_goes_on(rig) -> None:
    _twin, drives, can = rig
    with make_arm(can) as arm:
        arm.set_torque(True)
        for _ in range(5):
            arm.command(TARGET)
        arm.net.network.bus.shutdown()  # the adapter goes away under the arm ...
        sent = arm.command(TARGET)  # ... and the next command reconnects, then goes out
        assert np.all(np.isfinite(sent)) and arm.torque_enabled
        assert enabled(drives) == [1, 2, 3, 4, 5, 6]  # held, torque back on
        for _ in range(20):
            arm.command(TARGET)
        counts = arm.fault_counts()
        state = arm.read()
    assert counts["links_lost"] == 1 and counts["reconnects"] == 1, counts
    assert np.abs(state.positions - TARGET).max() < 0.05
    assert enabled(drives) == []  # torque off on exit


@pytest.mark.filterwarnings("error::pytest.PytestUnhandledThreadExceptionWarning")
def test_an_slcan_adapter_unplugged_from_its_pty_and_plugged_back_is_reopened(rig, tmp_path):
    """The SLCAN adapter's pty closed under the arm, a new one 0.3 s later behind the same
    link: the arm reopens ``slcan:LINK``, configures the drives again (still enabled), and
    goes on. python-can's reader thread does not die of the closed port (a traceback on
    stderr before): ``tolerant_slcan_bus`` keeps the error and waits."""
    import can

    from sim.canopen.server import SlcanPtyBridge

    _twin, drives, can_spec = rig
    bridge_bus = can.Bus(interface="virtual", channel=can_spec.split(":", 1)[1])
    try:
        with SlcanPtyBridge(bridge_bus, link=tmp_path / "ttyCAN") as bridge:
            cfg = CanArmConfig(  # the pty rig's PDO timeout
                heartbeat_ms=HEARTBEAT_MS, pdo_timeout_s=0.05, sdo_timeout_s=SDO_TIMEOUT_S
            )
            with CanArm(f"slcan:{bridge.port}", config=cfg) as arm:
                arm.set_torque(True)
                for _ in range(5):
                    arm.command(TARGET)
                bridge.unplug()
                threading.Timer(0.3, bridge.replug).start()
                for _ in range(20):
                    arm.command(TARGET)
                counts = arm.fault_counts()
                assert arm.torque_enabled and enabled(drives) == [1, 2, 3, 4, 5, 6]
            assert enabled(drives) == []
    finally:
        bridge_bus.shutdown()
    assert bridge.unplugs == 1
    assert counts["links_lost"] == 1 and counts["reconnects"] == 1, counts


@DEAD_NOTIFIER
def test_an_adapter_lost_for_good_stops_the_arm_after_bounded_attempts(rig) -> None:
    _twin, drives, can = rig
    fast = RecoveryPolicy(attempts=2, first_delay_s=0.05, max_delay_s=0.05)
    with make_arm(can, recovery=fast) as arm:
        arm.set_torque(True)
        arm.command(TARGET)
        # short SDO timeouts for the reconnections only: a connect at 50 ms failed once when the
        # machine was loaded (a full suite beside a campaign on 2 cores)
        arm.config = dataclasses.replace(arm.config, sdo_timeout_s=0.05)
        drives.stop()  # the drives drop off the bus (their side of the cable) ...
        arm.net.network.bus.shutdown()  # ... and the adapter fails
        with pytest.raises(SafetyStop) as info:
            arm.command(TARGET)
        message = str(info.value)
        assert "link lost" in message and "not back after 2 reconnection(s)" in message
        assert "\n" not in message
        counts = arm.fault_counts()
        assert counts["reconnect_attempts"] == 2 and counts["stops_after_link_loss"] == 1


@DEAD_NOTIFIER
@pytest.mark.parametrize("adapter", ["virtual", "slcan"])
def test_a_reconnection_that_fails_still_turns_the_drives_off_blind(rig, adapter, tmp_path):
    """The adapter fails under an arm holding torque, and every reconnection fails in the
    drives' configuration (e.g. their SDO answers lost on a garbled line): the network is
    closed, so the torque off is sent blind on a fresh handle of the adapter (a new virtual
    bus; the SLCAN lines written straight to the pty). Before, nothing was sent: the drives
    stayed in OPERATION ENABLED and the exit logged "'24640 not found in map'"."""
    import can

    from robot.canopen.network import CanNodeError
    from sim.canopen.server import SlcanPtyBridge

    _twin, drives, can_spec = rig
    bridge_bus = can.Bus(interface="virtual", channel=can_spec.split(":", 1)[1])
    bridge = SlcanPtyBridge(bridge_bus, link=tmp_path / "ttyCAN").__enter__()
    try:
        spec = can_spec if adapter == "virtual" else f"slcan:{bridge.port}"
        fast = RecoveryPolicy(attempts=2, first_delay_s=0.05, max_delay_s=0.05)
        cfg = CanArmConfig(
            heartbeat_ms=HEARTBEAT_MS, pdo_timeout_s=0.05, sdo_timeout_s=SDO_TIMEOUT_S
        )
        with CanArm(spec, config=cfg, recovery=fast) as arm:
            arm.set_torque(True)
            arm.command(TARGET)
            assert enabled(drives) == [1, 2, 3, 4, 5, 6]

            def unconfigurable() -> None:
                raise CanNodeError("node 1 (m1) does not answer SDO 0x1000 (injected)")

            arm._configure = unconfigurable
            arm.net.network.bus.shutdown()  # the adapter fails under the arm
            with pytest.raises(SafetyStop) as info:
                arm.command(TARGET)
            message = str(info.value)
            assert "\n" not in message and "not back after 2 reconnection(s)" in message
            assert "sent to node(s) 1, 2, 3, 4, 5, 6" in message, message
            deadline = time.monotonic() + BOUND_S
            while enabled(drives) and time.monotonic() < deadline:
                time.sleep(0.01)  # the bridge forwards the lines in its own thread
            assert enabled(drives) == []  # limp, as the emulator itself says
    finally:
        bridge.close()
        bridge_bus.shutdown()
