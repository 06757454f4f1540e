"""Whole turns on the Dynamixel bus: ``DynamixelArm`` over six emulated XL-320 (the hands of
``testkit.frozen_hands`` on a twin that is not stepped). A servo reads its angle about its
centre and counts no turns, so an offset in any turn (a joint calibration made on another
arm, or edited by hand) must read and command exactly as the same offset in the servo's own
turn; the calibration recovers the servos' mounting wherever their zero marks are in the
servo's range.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest

from calibration.joints import JointCalibration
from robot.angles import wrap
from robot.dynamixel.arm import DynamixelArm
from robot.dynamixel.control_table import XL320
from robot.spec import ergo_jr_spec
from sim.dynamixel.emulator import DynamixelEmulator, EmulatedSerial
from sim.twin import Twin
from testkit.frozen_hands import calibrate, first_torque_on

SPEC = ergo_jr_spec()
DIRECTIONS = np.array([1.0, -1.0, -1.0, 1.0, 1.0, -1.0])
# servo angle at each joint's zero mark, rad: a horn a tooth or two off (m1 and m4 use the
# servo's whole 300 degrees, so theirs stay near the centre)
ZERO_MARKS = np.radians([2.0, -20.0, 25.0, -3.0, 30.0, -15.0])
POSES = [np.zeros(6), np.radians([-140.0, 60.0, -60.0, 140.0, 50.0, -70.0])]


@pytest.fixture
def twin() -> Iterator[Twin]:
    t = Twin(render_size=(64, 64))
    yield t
    t.close()


def make_arm(emulator: DynamixelEmulator, cal: JointCalibration | None = None) -> DynamixelArm:
    connection = EmulatedSerial(emulator)
    if cal is None:  # raw servo angles: what a calibration reads
        return DynamixelArm("emulated", connection=connection)
    return DynamixelArm(
        "emulated",
        spec=cal.apply_to(SPEC),
        directions=cal.directions,
        offsets=cal.offsets,
        connection=connection,
    )


@pytest.mark.parametrize("turns", [0, 1, -2], ids=["own-turn", "a-turn-up", "two-turns-down"])
def test_offsets_in_any_turn_read_and_command_as_in_the_servos_own(twin, turns):
    """Was: an offset a turn off read every joint 2 pi away and sent every goal to the end of
    the servo's range."""
    emulator = DynamixelEmulator(twin, directions=DIRECTIONS, offsets=ZERO_MARKS)
    cal = calibrate(make_arm(emulator), twin)
    np.testing.assert_allclose(wrap(cal.offsets - ZERO_MARKS), 0.0, atol=XL320.rad_per_step)
    np.testing.assert_array_equal(cal.directions, DIRECTIONS)
    moved = JointCalibration(
        cal.names, cal.offsets + turns * math.tau, cal.directions, cal.lower, cal.upper
    )
    for q0 in POSES:
        q = first_torque_on(make_arm(emulator, moved), twin, q0)
        np.testing.assert_allclose(q, q0, atol=2 * XL320.rad_per_step)
        gaps = [s.peek("goal") - s.peek("position") for s in emulator.servos.values()]
        assert np.all(np.abs(gaps) <= 1), f"goal - position {gaps} steps at {q0}"
