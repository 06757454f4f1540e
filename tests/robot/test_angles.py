"""``robot.angles``, the one rule for whole turns: property-tested over raw angles and offsets
anywhere, several turns either way."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from robot.angles import (
    anchor,
    joint_angle,
    joint_angle_in_turn,
    mean_angle,
    raw_angle,
    spread,
    wrap,
)

ANGLES = st.floats(-5 * math.tau, 5 * math.tau, allow_nan=False)
JOINTS = st.floats(-math.radians(170.0), math.radians(170.0))  # every joint of the arm
DIRECTIONS = st.sampled_from([-1.0, 1.0])
TURNS = st.integers(-3, 3)
TOL = 1e-9


@given(ANGLES)
def test_wrap_lands_in_minus_pi_to_pi_and_keeps_the_angle(a):
    w = float(wrap(a))
    assert -math.pi < w <= math.pi
    assert abs(math.remainder(w - a, math.tau)) < TOL


@given(JOINTS, ANGLES, DIRECTIONS, TURNS, TURNS)
def test_a_joint_angle_does_not_depend_on_the_turn_of_the_reading_or_the_offset(
    q, offset, direction, k_raw, k_offset
):
    raw = raw_angle(q, offset, direction) + k_raw * math.tau
    assert abs(joint_angle(raw, offset + k_offset * math.tau, direction) - q) < TOL


@given(JOINTS, JOINTS, ANGLES, DIRECTIONS, TURNS)
def test_anchored_the_linear_conversions_agree_with_joint_angle_over_the_whole_range(
    q_now, q, offset, direction, k
):
    """Anchored to a reading (any turn), ``raw_angle`` and ``joint_angle_in_turn`` are each
    other's inverse and ``joint_angle``'s, for every joint angle of the range: the targets
    and limits a drive gets in its own increments are where the joint is read."""
    reading = raw_angle(q_now, offset, direction) + k * math.tau
    moved = anchor(offset, reading)
    assert abs(math.remainder(float(moved - offset), math.tau)) < TOL  # whole turns only
    raw = raw_angle(q, moved, direction)
    assert abs(joint_angle_in_turn(raw, moved, direction) - q) < TOL
    assert abs(joint_angle(raw, offset, direction) - q) < TOL
    assert abs(raw - reading) < 2 * math.radians(170.0) + TOL  # the reading's turn


@given(ANGLES, st.lists(st.floats(-0.03, 0.03), min_size=2, max_size=8))
def test_the_mean_of_readings_is_in_the_turn_of_the_first_never_wrapped(centre, jitter):
    readings = centre + np.asarray(jitter)
    wrapped = wrap(readings)  # as a reader that wraps reports them, across +-pi too
    m = float(mean_angle(wrapped))
    assert abs(m - wrapped[0]) < 0.07
    assert abs(math.remainder(m - (centre + np.mean(jitter)), math.tau)) < 1e-6
    assert float(spread(wrapped)) < 0.061
