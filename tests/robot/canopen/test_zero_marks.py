"""Zero marks anywhere on a drive's turn: a joint calibration made through ``CanArm`` over the
six emulated CiA 402 drives (the hands of ``testkit.frozen_hands`` on a twin that is not
stepped), then the calibrated arm's first torque on. The drives' zero marks read anywhere in
0..2 pi, past pi, and beyond one turn (a multi-turn encoder); with single-turn absolute
encoders the reading at power on lies in 0..2 pi, so a joint whose range straddles the
encoder's zero powers on a turn away from where it was calibrated.
"""

from __future__ import annotations

import math
import uuid
from collections.abc import Iterator

import numpy as np
import pytest

from calibration.joints import JointCalibration
from explore.rigs.canopen import can_offsets
from robot.angles import wrap
from robot.canopen.arm import CanArm, CanArmConfig
from robot.spec import ergo_jr_spec
from sim.canopen.drives import EmulatedDrives
from sim.twin import Twin
from testkit.frozen_hands import calibrate, first_torque_on, pose

SPEC = ergo_jr_spec()
HEARTBEAT_MS = 200
# how each drive is mounted: drive angle (counts x 2 pi / cpr) = direction * joint + zero mark
DIRECTIONS = np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0])
# near the limits of every joint, and the zero pose
POSES = [np.zeros(6), np.radians([-140.0, 110.0, -80.0, 140.0, 80.0, -100.0])]


def serve(twin: Twin, zero_marks: np.ndarray, **kw) -> tuple[EmulatedDrives, str]:
    """The six drives on a fresh virtual channel, their zero marks (drive angle at joint zero,
    rad) as given; returns them and the channel's spec."""
    can = f"virtual:zero-{uuid.uuid4().hex[:8]}"
    offsets = can_offsets(DIRECTIONS, zero_marks)  # the drives' convention is CanArm's
    drives = EmulatedDrives(twin, can, directions=DIRECTIONS, offsets=offsets, **kw)
    drives.start()
    return drives, can


def make_arm(can: str, cal: JointCalibration | None = None) -> CanArm:
    """The arm raw (drive angles: what a calibration reads) or calibrated with ``cal``."""
    if cal is None:
        return CanArm(can, config=CanArmConfig(heartbeat_ms=HEARTBEAT_MS))
    config = CanArmConfig(
        directions=tuple(cal.directions),
        offsets=tuple(can_offsets(cal.directions, cal.offsets)),
        heartbeat_ms=HEARTBEAT_MS,
    )
    return CanArm(can, spec=cal.apply_to(SPEC), config=config)


def holds(twin: Twin, drives: EmulatedDrives, can: str, cal: JointCalibration) -> None:
    """At each of ``POSES``: the calibrated arm reads the pose at torque on, and every drive's
    demand is where the drive is (to 2 increments of 65536 a turn)."""
    for q0 in POSES:
        q = first_torque_on(make_arm(can, cal), twin, q0)
        np.testing.assert_allclose(q, q0, atol=0.01)
        gaps = [d.demand - d.actual for d in drives.drives]
        assert np.all(np.abs(gaps) <= 2), f"demand - actual {gaps} increments at {q0}"


@pytest.fixture
def twin() -> Iterator[Twin]:
    t = Twin(render_size=(64, 64))
    yield t
    t.close()


# drive angle at each joint's zero mark, rad: m1 at 4.0 (past pi), the others anywhere on the
# turn and beyond it (a multi-turn encoder counts on from wherever it was zeroed)
ZERO_MARKS = np.array([4.0, 0.3, 5.9, 3.3 + math.tau, 2.0, -4.0])


def test_zero_marks_past_pi_are_kept_and_the_first_torque_on_holds_the_arm_where_it_is(twin):
    """Was: the zero pose read 4.0 rad on m1, saved as -2.283 (wrapped); the calibrated arm
    then read 6.284 rad at the zero mark, wrote 0x607D limits that exclude the drive's
    position, and its first goal at torque on was clamped -225 degrees away."""
    drives, can = serve(twin, ZERO_MARKS)
    try:
        cal = calibrate(make_arm(can), twin)
        # the zero marks, in whichever turn the arm reads them
        np.testing.assert_allclose(wrap(cal.offsets - ZERO_MARKS), 0.0, atol=0.01)
        np.testing.assert_array_equal(cal.directions, DIRECTIONS)
        holds(twin, drives, can, cal)
    finally:
        drives.stop()


@pytest.mark.parametrize(
    "zero_marks",
    [
        np.array([0.02, 6.27, math.pi, -math.pi + 0.01, 3 * math.tau + 1.0, -2 * math.tau - 0.5]),
        np.linspace(0.0, math.tau, 6, endpoint=False) + 0.5,
    ],
    ids=["at-the-turns-ends", "around-the-turn"],
)
def test_zero_marks_anywhere_on_the_turn_and_beyond(twin, zero_marks):
    drives, can = serve(twin, zero_marks)
    try:
        cal = calibrate(make_arm(can), twin)
        np.testing.assert_allclose(wrap(cal.offsets - zero_marks), 0.0, atol=0.01)
        holds(twin, drives, can, cal)
    finally:
        drives.stop()


def test_single_turn_encoders_powered_on_a_turn_away_from_the_calibration(twin):
    """Single-turn absolute encoders read 0..2 pi at power on. Zero marks near the turn's ends:
    calibrated at the zero pose, the drives then powered off and on again with every joint
    near a limit, where their readings are a turn away from the calibration's; the
    calibrated arm still reads the pose and holds it."""
    zero_marks = np.array([0.1, 6.2, 0.3, 6.0, 0.05, 6.25])
    drives, can = serve(twin, zero_marks, single_turn=True)
    try:
        cal = calibrate(make_arm(can), twin)
    finally:
        drives.stop()
    for q0 in POSES:
        pose(twin, q0)  # where the joints are when the drives power on
        drives, can = serve(twin, zero_marks, single_turn=True)
        try:
            turned = [d.turns for d in drives.drives]
            q = first_torque_on(make_arm(can, cal), twin, q0)
            np.testing.assert_allclose(q, q0, atol=0.01)
            gaps = [d.demand - d.actual for d in drives.drives]
            assert np.all(np.abs(gaps) <= 2), f"demand - actual {gaps} increments at {q0}"
        finally:
            drives.stop()
        if np.any(q0):
            assert any(turned), "no drive powered on a turn away: the test would prove nothing"
