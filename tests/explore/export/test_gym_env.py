"""The twin as Gymnasium environments: Gymnasium's own checker passes on both, a seeded rollout
is deterministic, the commands go through the Arm's safety, the reward relabels (GoalEnv
style), and closing turns the torque off."""

from __future__ import annotations

import warnings

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
        assert env.compute_reward(obs["achieved_goal"], obs["achieved_goal"], info) == 0.0
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
    twin = env.rig.twin
    assert twin.torque_enabled()
    env.close()
    assert not twin.torque_enabled() and not env.rig.arm.is_connected
