"""A stand-in whose CANopen drives read their joints' zero marks anywhere on the turn and
beyond it (``ergo twin serve --bus canopen --stand-in SEED --zero-marks anywhere``): the
draw, the hidden file, and a joint calibration over the served drives (the hands of
``testkit.frozen_hands``; the calibration is given the bus only, never the hidden file) that
recovers them, followed by the calibrated arm's first torque on, which holds the arm where it
is."""

from __future__ import annotations

import argparse
import json
import math
import uuid

import numpy as np
import pytest

from explore.rigs.canopen import can_offsets
from robot.angles import wrap
from robot.canopen.arm import CanArm, CanArmConfig
from robot.spec import ergo_jr_spec
from sim.canopen.server import drives_for
from sim.standin import hidden as H
from sim.standin.served import StandinError, open_served_rig
from testkit.frozen_hands import calibrate, first_torque_on
from testkit.standin_truth import joint_errors, read_hidden

SEEDS = range(300, 340)  # development stand-ins
SEED = 302  # its m1's zero mark reads 3.92 rad (mod one turn), 2.6 turns up
SPEC = ergo_jr_spec()
HEARTBEAT_MS = 200


def test_anywhere_changes_the_drives_zero_marks_only_and_covers_the_turn_and_beyond():
    marks = []
    for seed in SEEDS:
        horn, anywhere = H.draw_hidden(seed), H.draw_hidden(seed, "anywhere")
        assert json.dumps({**horn.to_dict(), "joints": None}) == json.dumps(
            {**anywhere.to_dict(), "joints": None}
        )
        np.testing.assert_array_equal(horn.offsets, anywhere.offsets)
        np.testing.assert_array_equal(horn.can_offsets, horn.offsets)  # "horn": the servos'
        marks.append(anywhere.can_offsets)
    marks = np.concatenate(marks)
    on_the_turn = np.mod(marks, math.tau)
    assert (on_the_turn > math.pi).mean() == pytest.approx(0.5, abs=0.1)
    assert on_the_turn.min() < 0.3 and on_the_turn.max() > math.tau - 0.3
    assert marks.min() < -math.tau and marks.max() > 2 * math.tau  # beyond one turn
    with pytest.raises(H.StandinError, match="--zero-marks must be one of horn, anywhere"):
        H.draw_hidden(1, "sideways")


def test_the_drives_zero_marks_are_written_and_read_back(tmp_path):
    rig = H.draw_hidden(SEED, "anywhere")
    back = read_hidden(H.write_hidden(rig, tmp_path / "h.json"))
    np.testing.assert_array_equal(back.can_offsets, rig.can_offsets)
    np.testing.assert_array_equal(back.offsets, rig.offsets)


def test_zero_marks_need_a_stand_in():
    with pytest.raises(StandinError, match="--zero-marks"):
        open_served_rig(argparse.Namespace(stand_in=None, zero_marks="anywhere"))


def test_a_stand_in_with_zero_marks_past_pi_calibrates_and_holds_at_its_first_torque_on(
    tmp_path,
):
    args = argparse.Namespace(stand_in=SEED, zero_marks="anywhere", hidden=tmp_path / "h.json")
    rig = open_served_rig(args)  # what `ergo twin serve` serves; the twin is not stepped
    truth = read_hidden(tmp_path / "h.json")  # the test's, never the calibration's
    assert np.any(np.mod(truth.can_offsets, math.tau) > math.pi)
    assert np.any(np.abs(truth.can_offsets) > math.tau)
    can = f"virtual:standin-{uuid.uuid4().hex[:8]}"
    drives = drives_for(rig, can)
    drives.start()
    try:
        raw = CanArm(can, config=CanArmConfig(heartbeat_ms=HEARTBEAT_MS))
        cal = calibrate(raw, rig.twin)
        errors, directions_right = joint_errors(truth, cal.to_dict(), bus="canopen")
        assert directions_right and np.all(errors < 0.5), errors  # deg
        config = CanArmConfig(
            directions=tuple(cal.directions),
            offsets=tuple(can_offsets(cal.directions, cal.offsets)),
            heartbeat_ms=HEARTBEAT_MS,
        )
        for q0 in (np.zeros(6), np.radians([120.0, -60.0, 60.0, -120.0, -60.0, 60.0])):
            arm = CanArm(can, spec=cal.apply_to(SPEC), config=config)
            q = first_torque_on(arm, rig.twin, q0)
            np.testing.assert_allclose(wrap(q - q0), 0.0, atol=0.01)
            gaps = [d.demand - d.actual for d in drives.drives]
            assert np.all(np.abs(gaps) <= 2), f"demand - actual {gaps} increments at {q0}"
    finally:
        drives.stop()
        rig.twin.close()
