"""The twin in process (``ergo_jr_twin``) as LeRobot drives a robot: what it observes, and the
arm's safety under LeRobot's calls (limits, the step bound, torque off on disconnect, on an
exception leaving ``with robot:`` and on SIGINT, before the script handles it)."""

from __future__ import annotations

import math
import os
import signal
import time

import numpy as np
import pytest
from lerobot_robot_ergo_jr import ErgoJrTwin, ErgoJrTwinConfig
from lerobot_robot_ergo_jr.features import IMAGE_KEY, JOINTS

from robot.spec import ERGO_JR_MAX_STEP, ergo_jr_spec

SPEC = ergo_jr_spec()


@pytest.fixture
def robot():
    r = ErgoJrTwin(ErgoJrTwinConfig())
    r.connect()
    yield r
    r.disconnect()


def _action(**joints: float) -> dict[str, float]:
    out = dict.fromkeys(JOINTS, 0.0)
    out.update({f"{k}.pos": v for k, v in joints.items()})
    return out


def test_it_observes_the_joints_and_the_overhead_frame_and_follows_wall_time(robot):
    obs = robot.get_observation()
    assert list(obs) == [*JOINTS, IMAGE_KEY]
    assert all(isinstance(obs[j], float) for j in JOINTS)
    image = obs[IMAGE_KEY]
    assert image.shape == (64, 64, 3) and image.dtype == np.uint8
    t0 = robot.twin.time
    time.sleep(0.3)
    robot.get_observation()
    assert robot.twin.time - t0 >= 0.25  # physics caught up with the wall clock


def test_an_action_is_clamped_to_the_limits_and_to_the_step_bound(robot):
    sent = robot.send_action(_action(m1=10.0, m3=-10.0))
    assert sent["m1.pos"] == pytest.approx(ERGO_JR_MAX_STEP)
    assert sent["m3.pos"] == pytest.approx(-ERGO_JR_MAX_STEP)
    for _ in range(40):
        sent = robot.send_action(_action(m1=10.0, m3=-10.0))
    assert sent["m1.pos"] == pytest.approx(SPEC.upper[0])
    assert sent["m3.pos"] == pytest.approx(SPEC.lower[2])
    time.sleep(1.0)  # the twin follows in real time
    obs = robot.get_observation()
    assert obs["m1.pos"] == pytest.approx(SPEC.upper[0], abs=math.radians(3))


def test_a_tighter_max_relative_target_holds():
    r = ErgoJrTwin(ErgoJrTwinConfig(max_relative_target=0.05, camera=False))
    r.connect()
    try:
        assert IMAGE_KEY not in r.get_observation()
        steps = [r.send_action(_action(m2=1.0))["m2.pos"] for _ in range(3)]
        np.testing.assert_allclose(steps, [0.05, 0.10, 0.15])
    finally:
        r.disconnect()


def test_a_bad_action_is_refused_in_one_line_and_nothing_is_sent(robot):
    before = robot.twin.targets().copy()
    with pytest.raises(ValueError, match="lacks joint"):
        robot.send_action({"m1.pos": 0.1})
    with pytest.raises(ValueError, match="not a number"):
        robot.send_action({**_action(), "m2.pos": "up"})
    with pytest.raises(ValueError, match="non-finite"):
        robot.send_action(_action(m4=float("nan")))
    np.testing.assert_array_equal(robot.twin.targets(), before)


def test_torque_goes_off_on_disconnect():
    r = ErgoJrTwin(ErgoJrTwinConfig(camera=False))
    r.connect()
    assert r.twin.torque_enabled()
    r.disconnect()
    assert not r.twin.torque_enabled() and not r.is_connected
    r.disconnect()  # a second call (a script's finally after a failure) does nothing


def test_torque_goes_off_when_an_exception_leaves_the_robot():
    r = ErgoJrTwin(ErgoJrTwinConfig(camera=False))
    with pytest.raises(RuntimeError, match="a policy crashed"), r:
        r.send_action(_action(m1=0.1))
        raise RuntimeError("a policy crashed")
    assert not r.twin.torque_enabled()


def test_sigint_cuts_torque_before_the_script_sees_the_interrupt():
    r = ErgoJrTwin(ErgoJrTwinConfig(camera=False))
    r.connect()
    torque_when_handled = None
    try:
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(100):  # the interrupt is raised between two bytecodes
            time.sleep(0.01)
    except KeyboardInterrupt:
        torque_when_handled = r.twin.torque_enabled()  # before any disconnect
    finally:
        r.disconnect()
    assert torque_when_handled is False
