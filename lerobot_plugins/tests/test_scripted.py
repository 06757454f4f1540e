"""The scripted teleoperator: the same motions for a seed, inside the joint limits, smooth
enough for the arm's step bound at LeRobot's rates, going on for as long as asked."""

from __future__ import annotations

import numpy as np
import pytest
from lerobot_robot_ergo_jr.features import JOINTS
from lerobot_teleoperator_ergo_jr import ErgoJrScripted, ErgoJrScriptedConfig
from lerobot_teleoperator_ergo_jr.scripted import MotionScript

from robot.spec import ERGO_JR_MAX_STEP, ergo_jr_spec

SPEC = ergo_jr_spec()
TIMING = {"lead_s": 0.5, "return_s": 1.0, "pause_s": 0.5, "max_speed": 3.0}


def _path(seed: int, seconds: float, rate: float) -> np.ndarray:
    script = MotionScript(seed, **TIMING)
    return np.array([script.at(t) for t in np.arange(0.0, seconds, 1.0 / rate)])


def test_a_seed_gives_the_same_motions_and_another_seed_others():
    a, b, c = _path(3, 12.0, 30), _path(3, 12.0, 30), _path(4, 12.0, 30)
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).max() > 0.3
    assert np.abs(a[0] - SPEC.rest).max() == 0.0  # it starts at rest
    assert np.ptp(a, axis=0).min() > 0.05  # every joint moves


@pytest.mark.parametrize("rate", [30, 60])
def test_the_motions_stay_inside_the_limits_and_within_the_step_bound(rate):
    path = _path(0, 30.0, rate)
    assert np.all(path >= SPEC.lower - 1e-9) and np.all(path <= SPEC.upper + 1e-9)
    # slowed to 3 rad/s: under the arm's 0.15 rad bound per tick at 30 Hz and more, so the
    # follower plays them unclipped (at the primitive's own rate they move up to 0.6 rad a tick)
    fastest = np.abs(np.diff(path, axis=0)).max()
    assert fastest <= 3.0 / rate + 1e-9 and fastest < ERGO_JR_MAX_STEP


def test_its_keyframes_do_not_pile_up_over_a_long_run():
    script = MotionScript(0, **TIMING)
    for t in np.arange(0.0, 600.0, 0.5):
        script.at(t)
    assert len(script._times) < 200


def test_as_a_teleoperator_it_gives_the_joints_from_connect_on():
    teleop = ErgoJrScripted(ErgoJrScriptedConfig(seed=1))
    teleop.connect()
    try:
        action = teleop.get_action()
        assert list(action) == list(JOINTS)
        assert all(isinstance(v, float) for v in action.values())
    finally:
        teleop.disconnect()
    assert not teleop.is_connected
