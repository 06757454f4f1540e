"""A LeRobot user's path on the twin, every step a LeRobot command as docs/lerobot.md gives it:
calibrate, teleoperate and record with the scripted teleoperator, train a small policy on the
recording and on an ``ergo export lerobot`` dataset of an exploration, roll the policy out on
the twin (``lerobot-eval`` on the environment, recording its rollout; ``lerobot-rollout`` on
the robot)."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from explore.export.lerobot import JOINT_FEATURES, ROBOT_TYPE, VIDEO_KEY
from lerobot_plugins.tests.harness import note, report, report_dataset, run_lerobot, tail

FPS = 30
EPISODES = 2
EPISODE_S = 4
# A small ACT (LeRobot's action-chunking transformer) and a few steps: the path, not a policy
# worth having. No pretrained backbone: nothing is downloaded.
TRAIN = [
    "--policy.type=act", "--policy.device=cpu", "--policy.push_to_hub=false",
    "--policy.pretrained_backbone_weights=null", "--policy.dim_model=64", "--policy.n_heads=2",
    "--policy.dim_feedforward=128", "--policy.n_encoder_layers=1",
    "--policy.n_decoder_layers=1", "--policy.n_vae_encoder_layers=1",
    "--policy.chunk_size=10", "--policy.n_action_steps=10", "--steps=3", "--batch_size=4",
    "--num_workers=0", "--log_freq=1", "--save_freq=3", "--wandb.enable=false",
]  # fmt: skip


def _ok(done: subprocess.CompletedProcess[str]) -> str:
    assert done.returncode == 0, tail(done)
    return done.stdout + done.stderr


def _info(dataset: Path) -> dict:
    return json.loads((dataset / "meta/info.json").read_text())


def _frames(dataset: Path) -> dict[str, np.ndarray]:
    table = pq.read_table(dataset / "data/chunk-000/file-000.parquet").to_pydict()
    return {k: np.asarray(v) for k, v in table.items()}


def _train(dataset: Path, repo_id: str, out: Path) -> Path:
    args = [
        "train",
        f"--dataset.repo_id={repo_id}",
        f"--dataset.root={dataset}",
        *TRAIN,
        f"--output_dir={out}",
    ]  # fmt: skip
    _ok(run_lerobot(*args))
    model = out / "checkpoints/last/pretrained_model"
    assert (model / "model.safetensors").is_file()
    return model


@pytest.mark.timeout(3000)
def test_the_twin_path_from_calibration_to_a_rolled_out_policy(tmp_path):
    robot = ["--robot.type=ergo_jr_twin"]
    said = _ok(run_lerobot("calibrate", *robot))
    assert "nothing to calibrate" in said

    args = [
        "teleoperate",
        *robot,
        "--teleop.type=ergo_jr_scripted",
        "--teleop_time_s=3",
        f"--fps={FPS}",
    ]  # fmt: skip
    said = _ok(run_lerobot(*args))
    assert "Teleop loop time" in said and "disconnected (torque off)" in said

    dataset = tmp_path / "twin_scripted"
    args = [
        "record",
        *robot,
        "--teleop.type=ergo_jr_scripted",
        "--teleop.seed=3",
        "--dataset.repo_id=local/twin_scripted",
        f"--dataset.root={dataset}",
        f"--dataset.num_episodes={EPISODES}",
        f"--dataset.episode_time_s={EPISODE_S}",
        "--dataset.reset_time_s=1",
        f"--dataset.fps={FPS}",
        "--dataset.single_task=scripted motions",
        "--dataset.push_to_hub=false",
        "--play_sounds=false",
    ]  # fmt: skip
    _ok(run_lerobot(*args))
    info = report_dataset(dataset)
    assert info["robot_type"] == ROBOT_TYPE and info["fps"] == FPS
    assert info["total_episodes"] == EPISODES
    assert 0.3 * EPISODES * EPISODE_S * FPS < info["total_frames"] <= EPISODES * EPISODE_S * FPS + 2
    feats = info["features"]
    assert feats["observation.state"]["names"] == feats["action"]["names"] == list(JOINT_FEATURES)
    assert feats[VIDEO_KEY]["shape"] == [64, 64, 3] and feats[VIDEO_KEY]["dtype"] == "video"
    frames = _frames(dataset)
    state, action = frames["observation.state"], frames["action"]
    assert np.ptp(action, axis=0).max() > 0.3  # the scripted motions moved the arm...
    lag = 3  # ...and it followed them, a few ticks behind (the twin's servos)
    assert np.median(np.abs(state[lag:] - action[:-lag])) < 0.05

    model = _train(dataset, "local/twin_scripted", tmp_path / "train_recorded")

    evaluated = tmp_path / "eval"
    args = [
        "eval",
        f"--policy.path={model}",
        "--env.type=ergo_jr",
        f"--env.fps={FPS}",
        "--env.episode_length=30",
        "--eval.n_episodes=2",
        "--eval.batch_size=2",
        "--eval.use_async_envs=false",
        "--eval.recording=true",
        "--policy.device=cpu",
        f"--output_dir={evaluated}",
    ]  # fmt: skip
    said = _ok(run_lerobot(*args))
    result = json.loads((evaluated / "eval_info.json").read_text())["overall"]
    assert result["n_episodes"] == 2
    report(
        f"eval_info.json: {result['n_episodes']} episodes, avg_sum_reward "
        f"{result['avg_sum_reward']}, pc_success {result['pc_success']}"
    )
    for env in range(2):  # one twin per episode, side by side (batch_size 2)
        rollout = _frames(evaluated / f"recordings/ergo_jr_0/env_{env}")
        assert len(rollout["action"]) == 30
        moved = np.ptp(rollout["agent_pos"], axis=0)
        report(
            f"rollout {env}: {len(rollout['action'])} steps, each joint's range "
            f"{moved.round(3)} rad"
        )
        assert moved.max() > 0.05  # the policy moved the twin

    args = [
        "rollout",
        "--strategy.type=base",
        f"--policy.path={model}",
        *robot,
        "--task=scripted motions",
        "--duration=3",
        f"--fps={FPS}",
        "--policy.device=cpu",
    ]  # fmt: skip
    said = _ok(run_lerobot(*args))
    assert "Rollout finished" in said and "disconnected (torque off)" in said


@pytest.mark.timeout(1500)
def test_an_exported_exploration_trains_a_policy_for_the_twin(tmp_path):
    ergo = [sys.executable, "-m", "explore.cli"]
    run = tmp_path / "run"
    steps = [
        ["explore", "--rig", "sim", "--strategy", "rpe", "--episodes", "3", "--seed", "0",
         "--out", str(run), "--rig-option", "record_video=64"],
        ["export", "lerobot", str(run), "--out", str(tmp_path / "exported")],
    ]  # fmt: skip
    for args in steps:
        t0 = time.monotonic()
        done = subprocess.run([*ergo, *args], capture_output=True, text=True, timeout=900)
        note(f"ergo {' '.join(args)}", done.returncode, time.monotonic() - t0)
        assert done.returncode == 0, tail(done)
    exported = tmp_path / "exported"
    info = report_dataset(exported)
    assert info["robot_type"] == ROBOT_TYPE and info["total_frames"] == 3 * 40
    model = _train(exported, "local/exported", tmp_path / "train_exported")
    config = json.loads((model / "config.json").read_text())
    assert set(config["input_features"]) == {"observation.state", VIDEO_KEY}
    assert config["output_features"]["action"]["shape"] == [6]
