"""The twin as Gymnasium environments: Gymnasium's own checker passes on both, a seeded rollout
is deterministic, the commands go through the Arm's safety, the reward relabels (GoalEnv
style), closing turns the torque off, the specs serialise, and async vectorisation works after
the parent process used an environment."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")
from gymnasium.utils.env_checker import check_env  # noqa: E402

import explore.export.gym_env as gym_env  # noqa: E402 - registers the environments

IDS = ("ergo_explore/ArmBall-v0", "ergo_explore/ArmBallDmp-v0")


@pytest.mark.parametrize("env_id", IDS)
def test_gymnasiums_env_checker_passes(env_id):
    env = gym.make(env_id, render_mode="rgb_array")
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env.unwrapped)  # raises on any failed check
        # the one remark: per-tick actions are joint targets in rad, not a [-1, 1] box
        remarks = [
            str(w.message) for w in caught if "symmetric and normalized" not in str(w.message)
        ]
        assert remarks == []
        env.reset(seed=0)
        frame = env.render()
        assert (
            frame.shape == (gym_env.RENDER_SIDE, gym_env.RENDER_SIDE, 3) and frame.dtype == np.uint8
        )
    finally:
        env.close()


def test_normalized_actions_pass_the_checker_without_remarks_and_span_the_joint_ranges():
    env = gym.make(IDS[0], normalized_actions=True)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env.unwrapped)
        assert [str(w.message) for w in caught] == []
        assert env.action_space == gym.spaces.Box(-1.0, 1.0, (6,), np.float32)
        spec = env.unwrapped.spec_arm
        targets = env.unwrapped.joint_targets
        np.testing.assert_allclose(targets(-np.ones(6)), spec.lower)
        np.testing.assert_allclose(targets(np.ones(6)), spec.upper)
        np.testing.assert_allclose(targets(np.zeros(6)), (spec.lower + spec.upper) / 2)
        np.testing.assert_allclose(targets(np.full(6, 5.0)), spec.upper)  # clipped to the box
        env.reset(seed=0)
        _, _, _, _, info = env.step(np.ones(6, dtype=np.float32))
        step = np.clip(spec.upper - spec.rest, -spec.max_step, spec.max_step)
        np.testing.assert_allclose(info["command_sent"], spec.rest + step, atol=1e-9)
    finally:
        env.close()
    default = gym.make(IDS[0])  # v0 keeps its radians
    try:
        np.testing.assert_allclose(default.action_space.high, default.unwrapped.spec_arm.upper)
    finally:
        default.close()


@pytest.mark.parametrize("env_id", IDS)
def test_the_specs_serialise_and_make_the_same_environment(env_id):
    from gymnasium.envs.registration import EnvSpec

    kwargs = {"normalized_actions": True} if env_id == IDS[0] else {}
    env = gym.make(env_id, render_mode="rgb_array", **kwargs)
    try:
        text = env.spec.to_json()  # raised on a callable entry point
        assert EnvSpec.from_json(gym.spec(env_id).to_json()) == gym.spec(env_id)
        again = gym.make(EnvSpec.from_json(text))
        try:
            assert again.action_space == env.action_space
            assert again.unwrapped.render_mode == "rgb_array"
        finally:
            again.close()
    finally:
        env.close()


# Run in a fresh interpreter, so that a hang times out and its process group is killed (workers
# included) instead of blocking the suite: use an environment in the parent (check_env, reset,
# render), keep it open, then vectorise with the default start method (fork on Linux).
_ASYNC_AFTER_USE = """
import gymnasium as gym
import numpy as np
from gymnasium.utils.env_checker import check_env
import explore.export.gym_env  # noqa: F401

env = gym.make("ergo_explore/ArmBall-v0", render_mode="rgb_array", normalized_actions=True)
check_env(env.unwrapped)
env.reset(seed=1)
env.render()
vec = gym.make_vec(
    "ergo_explore/ArmBall-v0", num_envs=2, vectorization_mode="async", normalized_actions=True
)
obs, _ = vec.reset(seed=0)  # env i is seeded 0 + i
for _ in range(3):
    vec.step(vec.action_space.sample())
vec.close()
for i in range(2):  # the workers rendered what the parent renders for the same seed
    mine, _ = env.reset(seed=i)
    assert np.array_equal(obs["image"][i], mine["image"]), i
    assert np.array_equal(obs["desired_goal"][i], mine["desired_goal"]), i
env.close()
print("async after use: ok")
"""


def test_async_vectorisation_works_after_the_parent_used_an_environment():
    env = {k: v for k, v in os.environ.items() if k != "LP_NUM_THREADS"}  # the default
    env["PYTHONPATH"] = str(Path(__file__).resolve().parents[3])
    proc = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(_ASYNC_AFTER_USE)],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )
    try:
        out, _ = proc.communicate(timeout=120)  # about 2 s idle; hung forever before
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)  # the workers too
        proc.communicate()
        pytest.fail("async vectorisation hung after the parent used an environment")
    assert proc.returncode == 0 and "async after use: ok" in out, out


def _rollout(env_id: str, seed: int, steps: int) -> list:
    env = gym.make(env_id)
    try:
        obs, _ = env.reset(seed=seed)
        env.action_space.seed(seed)
        out = [obs]
        for _ in range(steps):
            obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
            out.append((obs, reward))
            if terminated or truncated:
                break
        return out
    finally:
        env.close()


def _same(a, b) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, tuple):
        return all(_same(x, y) for x, y in zip(a, b, strict=True))
    return bool(np.array_equal(a, b))


@pytest.mark.parametrize("env_id, steps", [(IDS[0], 25), (IDS[1], 1)])
def test_a_seeded_rollout_is_deterministic(env_id, steps):
    a, b = _rollout(env_id, 11, steps), _rollout(env_id, 11, steps)
    assert len(a) == len(b) == steps + 1 and all(_same(x, y) for x, y in zip(a, b, strict=True))
    other = _rollout(env_id, 12, 0)
    assert not np.array_equal(other[0]["desired_goal"], a[0]["desired_goal"])


def test_per_tick_commands_go_through_the_arms_safety():
    env = gym.make(IDS[0]).unwrapped
    try:
        env.reset(seed=0)
        spec = env.rig.arm.spec
        far = spec.upper + 1.0  # beyond every limit and far beyond one step
        _, _, _, _, info = env.step(far)
        sent = info["command_sent"]
        assert np.all(np.abs(sent - spec.rest) <= spec.max_step + 1e-9)  # one step from rest
        for _ in range(60):
            _, _, _, _, info = env.step(far)
        assert np.all(info["command_sent"] <= spec.upper + 1e-9)  # held at the limits
    finally:
        env.close()


def test_the_reward_relabels_like_a_goal_env():
    env = gym.make(IDS[0]).unwrapped
    try:
        obs, info = env.reset(seed=3)
        achieved = np.stack([obs["achieved_goal"]] * 4)
        goals = achieved + np.array([[0, 0], [0.01, 0], [0.05, 0], [0, -0.2]])
        np.testing.assert_array_equal(
            env.compute_reward(achieved, goals, [info] * 4), [0, 0, -1, -1]
        )
        success = env.compute_reward(obs["achieved_goal"], obs["achieved_goal"], info)
        assert success == 0.0 and not np.signbit(success)  # 0.0, not -0.0
        assert not np.signbit(env.compute_reward(achieved, achieved, [info] * 4)).any()
        assert info["is_success"] == (
            env.compute_reward(obs["achieved_goal"], obs["desired_goal"]) == 0
        )
    finally:
        env.close()


def test_one_dmp_step_is_one_episode_that_can_move_the_ball():
    env = gym.make(IDS[1]).unwrapped
    try:
        moved = 0
        for seed in range(6):
            env.reset(seed=seed)
            theta = np.random.default_rng(seed).uniform(-1, 1, 48)
            after, reward, terminated, truncated, info = env.step(theta)
            assert terminated and not truncated
            assert reward in (0.0, -1.0)
            np.testing.assert_allclose(after["observation"], env.rig.arm.spec.rest, atol=0.1)
            moved += info["ball_moved"]
        assert moved >= 1  # random parameters move the ball in a clear fraction of episodes
    finally:
        env.close()


def test_closing_turns_the_torque_off():
    env = gym.make(IDS[0]).unwrapped
    env.reset(seed=0)
    twin = env.twin
    assert twin.torque_enabled()
    env.close()
    assert not twin.torque_enabled() and not env.rig.arm.is_connected


@pytest.mark.parametrize("env_id", IDS)
def test_compute_terminated_and_truncated_give_what_step_returns(env_id):
    env = gym.make(env_id).unwrapped
    try:
        env.reset(seed=4)
        action = np.zeros(env.action_space.shape, dtype=np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        achieved, desired = obs["achieved_goal"], obs["desired_goal"]
        assert reward == env.compute_reward(achieved, desired, info)
        assert terminated == env.compute_terminated(achieved, desired, info)
        assert truncated == env.compute_truncated(achieved, desired, info) is False
        assert terminated is (env_id == IDS[1])  # a DMP step is a whole episode
        batch = np.stack([achieved] * 3)
        assert env.compute_terminated(batch, batch, [info] * 3).shape == (3,)
        assert not env.compute_truncated(batch, batch, [info] * 3).any()
    finally:
        env.close()
