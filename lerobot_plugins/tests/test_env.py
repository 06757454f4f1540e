"""The twin as LeRobot's environment (``--env.type=ergo_jr``), built by LeRobot's own
``make_env``: its observations become the policy's features, its steps go through the arm's
safety, and it observes what the ``ergo_jr_twin`` robot observes."""

from __future__ import annotations

import numpy as np
import pytest
from lerobot.envs.factory import make_env
from lerobot.envs.utils import preprocess_observation
from lerobot_env_ergo_jr import ErgoJrEnvConfig

from robot.spec import ERGO_JR_MAX_STEP, ergo_jr_spec

SPEC = ergo_jr_spec()


@pytest.fixture(scope="module")
def vec_env():
    envs = make_env(ErgoJrEnvConfig(fps=30, episode_length=20), n_envs=1)
    env = envs["ergo_jr"][0]
    yield env
    env.close()


def test_make_env_builds_it_and_its_observation_becomes_the_policys_features(vec_env):
    obs, _ = vec_env.reset(seed=0)
    batch = preprocess_observation(obs)
    assert batch["observation.state"].shape == (1, 6)
    assert batch["observation.images.overhead"].shape == (1, 3, 64, 64)
    assert vec_env.call("_max_episode_steps")[0] == 20
    assert vec_env.call("task_description")[0]


def test_a_step_is_clamped_by_the_arm_and_lasts_one_tick(vec_env):
    obs, _ = vec_env.reset(seed=1)
    inner = vec_env.envs[0].unwrapped
    t0 = inner.inner.twin.time
    target = np.full((1, 6), 3.0, dtype=np.float32)
    _, reward, terminated, truncated, info = vec_env.step(target)
    sent = info["command_sent"][0]
    np.testing.assert_allclose(sent, obs["agent_pos"][0] + ERGO_JR_MAX_STEP, atol=1e-5)
    assert inner.inner.twin.time - t0 == pytest.approx(1 / 30, abs=0.006)
    assert reward[0] in (-1.0, 0.0) and not terminated[0] and not truncated[0]


def test_it_sees_what_the_twin_robot_sees():
    from lerobot_env_ergo_jr.env import ErgoJrTwinEnv
    from lerobot_robot_ergo_jr import ErgoJrTwin, ErgoJrTwinConfig

    env = ErgoJrTwinEnv(image_side=64)
    robot = ErgoJrTwin(ErgoJrTwinConfig())
    robot.connect()
    try:
        obs, _ = env.reset(seed=0)
        twin = env.inner.twin
        with robot.twin.lock:  # the robot's twin put in the environment's state
            robot.twin.set_state(twin.get_state())
        seen = robot.render(robot.overhead)
        np.testing.assert_array_equal(seen, obs["pixels"]["overhead"])
        other = ErgoJrTwinEnv(image_side=96)
        obs96, _ = other.reset(seed=0)
        assert obs96["pixels"]["overhead"].shape == (96, 96, 3)
        other.close()
    finally:
        robot.disconnect()
        env.close()
