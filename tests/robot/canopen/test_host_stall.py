"""A host whose process stalls (a C call that holds the GIL, as loading torch's libraries does
for 0.4 s here) does not call its drives lost for heartbeats it could not read: the silence
right after its own stall is excused within ``health.BEHIND_HEARTBEAT_GRACE``
(``robot/canopen/health.py``), and a node still silent once the host runs again is lost."""

from __future__ import annotations

import time
import uuid
from collections.abc import Iterator

import numpy as np
import pytest

from robot import SafetyStop
from robot.canopen import health
from robot.canopen.arm import CanArm, CanArmConfig
from sim.canopen.drives import EmulatedDrives
from sim.twin import Twin
from testkit.gil import hold_the_gil

HEARTBEAT_MS = 200
LIMIT_S = 1.5 * HEARTBEAT_MS / 1000  # CanArmConfig's heartbeat_factor default
STALL_S = 2 * LIMIT_S  # past the limit, within the grace (3 limits)


@pytest.fixture
def arm() -> Iterator[tuple[CanArm, EmulatedDrives]]:
    channel = f"virtual:stall-{uuid.uuid4().hex[:8]}"
    drives = EmulatedDrives(Twin(), channel, sync_step_s=0.025)
    drives.start()
    arm = CanArm(channel, config=CanArmConfig(heartbeat_ms=HEARTBEAT_MS))
    try:
        arm.connect()
        arm.set_torque(True)
        yield arm, drives
    finally:
        arm.disconnect()
        drives.stop()


@pytest.mark.parametrize("trial", range(3))
def test_a_stalled_host_goes_on_once_it_runs_again(arm, trial):
    arm, _ = arm
    start = arm.read().positions
    hold_the_gil(STALL_S)
    for _ in range(10):  # commands and reads at 40 Hz after the stall: no stop
        arm.command(start)
        assert np.isfinite(arm.read().positions).all()
        time.sleep(0.025)


def test_a_node_silent_after_the_stall_is_still_lost(arm):
    arm, drives = arm
    start = arm.read().positions
    drives.stop_heartbeat(3)
    hold_the_gil(STALL_S)
    deadline = time.monotonic() + 3 * health.BEHIND_HEARTBEAT_GRACE * LIMIT_S
    with pytest.raises(SafetyStop, match=r"node 3 .* lost: no heartbeat"):
        while time.monotonic() < deadline:
            arm.command(start)
            time.sleep(0.025)
    assert np.isfinite(start).all()
