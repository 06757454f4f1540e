"""The LeRobot user's path against ``ergo twin serve`` over both buses (the drivers a real arm
gets), the leader a second served twin moved by its hands; and the arm's safety when a LeRobot
script is stopped by Ctrl-C, killed, or ends on an exception."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from explore.export.lerobot import JOINT_FEATURES, ROBOT_TYPE, VIDEO_KEY
from lerobot_plugins.tests.harness import (
    BIN,
    ENV,
    bus_flag,
    nominal_joint_calibration,
    note,
    report,
    report_dataset,
    run_lerobot,
    tail,
)
from sim.standin.hands import HandsError
from testkit.standin_owner import Owner, ServedRig

CALIBRATION = Path(ENV["ERGO_CALIBRATION_DIR"])
# Where the leader's hands hold it while the follower is driven, rad (inside every limit).
POSE = {"m1": 0.6, "m2": 0.3, "m3": -0.4}
FPS = 30
# How close the follower comes to the leader's pose by the end of a recording, rad: the twin's
# servos under gravity stop a degree or two short of a goal (guess, on the safe side).
FOLLOW_RAD = math.radians(4.0)
LOOP_BOUND_S = 300.0  # a LeRobot command to reach its loop, against hangs (not a target)


def _ok(done: subprocess.CompletedProcess[str]) -> str:
    assert done.returncode == 0, tail(done)
    return done.stdout + done.stderr


def _calibrate(owner: Owner, device: str, kind: str, rig: ServedRig) -> None:
    """``lerobot-calibrate`` for a robot or a leader, the served twin's hands answering."""
    args = [f"--{device}.type={kind}", bus_flag(rig, device), f"--{device}.id={owner.rig_id}"]
    step = owner.calibrate_joints(command=[str(BIN / "lerobot-calibrate"), *args])
    note(f"lerobot-calibrate {' '.join(args)}", step.rc, step.seconds)


@pytest.mark.timeout(3000)
@pytest.mark.parametrize("bus", ["dynamixel", "canopen"])
def test_calibrate_teleoperate_and_record_over_the_bus_with_a_leader_arm(bus, tmp_path):
    follower_id, leader_id = f"follower-{bus}", f"leader-{bus}"
    with (
        ServedRig(bus, None, log=tmp_path / "follower.log") as follower,
        ServedRig(bus, None, flags=["--no-camera"], log=tmp_path / "leader.log") as leader,
    ):
        f_owner = Owner(follower, follower_id, CALIBRATION)
        l_owner = Owner(leader, leader_id, CALIBRATION)
        # The two pairs of hands at once on the Dynamixel bus; one after the other over SLCAN,
        # where two at once lost a drive's heartbeat (0.86 s against 0.75 s) at load 13 on 2 cores
        with ThreadPoolExecutor(2 if bus == "dynamixel" else 1) as pool:
            jobs = [
                pool.submit(_calibrate, f_owner, "robot", f"ergo_jr_{bus}", follower),
                pool.submit(_calibrate, l_owner, "teleop", "ergo_jr_leader", leader),
            ]
            for job in jobs:
                job.result()
        for rig_id in (follower_id, leader_id):  # the files ergo calibrate joints writes
            doc = json.loads((CALIBRATION / rig_id / "joints.json").read_text())
            assert doc["kind"] == "joints" and doc["rig_id"] == rig_id

        with l_owner.hands() as hands:  # the leader held at a pose, limp
            hands.move(POSE)
        robot = [
            f"--robot.type=ergo_jr_{bus}",
            bus_flag(follower, "robot"),
            f"--robot.id={follower_id}",
        ]
        teleop = [
            "--teleop.type=ergo_jr_leader",
            bus_flag(leader, "teleop"),
            f"--teleop.id={leader_id}",
        ]
        said = _ok(run_lerobot("teleoperate", *robot, *teleop, "--teleop_time_s=3"))
        assert "Teleop loop time" in said
        assert f_owner.torque_read_back() == [False] * 6  # off once LeRobot disconnected
        assert l_owner.torque_read_back() == [False] * 6  # the leader stays limp

        dataset = tmp_path / "leader"
        args = [
            "record", *robot, f"--robot.camera={follower.camera_url}", *teleop,
            "--dataset.repo_id=local/leader", f"--dataset.root={dataset}",
            "--dataset.num_episodes=1", "--dataset.episode_time_s=4", f"--dataset.fps={FPS}",
            "--dataset.single_task=follow the leader", "--dataset.push_to_hub=false",
            "--play_sounds=false",
        ]  # fmt: skip
        _ok(run_lerobot(*args))
        assert f_owner.torque_read_back() == [False] * 6

    info = report_dataset(dataset)
    assert info["robot_type"] == ROBOT_TYPE and info["total_episodes"] == 1
    assert info["total_frames"] > 0.3 * 4 * FPS
    feats = info["features"]
    assert feats["observation.state"]["names"] == list(JOINT_FEATURES)
    assert feats[VIDEO_KEY]["shape"] == [64, 64, 3]
    table = pq.read_table(dataset / "data/chunk-000/file-000.parquet").to_pydict()
    action, state = np.asarray(table["action"]), np.asarray(table["observation.state"])
    pose = np.array([POSE.get(j.removesuffix(".pos"), 0.0) for j in JOINT_FEATURES])
    np.testing.assert_allclose(action[-5:], np.tile(pose, (5, 1)), atol=math.radians(1.0))
    off = np.degrees(np.abs(state[-5:] - pose).max())
    report(f"the follower's last 5 frames within {off:.2f} deg of the leader's pose")
    np.testing.assert_allclose(state[-5:], np.tile(pose, (5, 1)), atol=FOLLOW_RAD)


# ---- safety under LeRobot's scripts, on the Dynamixel bus ---------------------------------
@pytest.fixture(scope="module")
def follower(tmp_path_factory):
    log = tmp_path_factory.mktemp("served") / "follower.log"
    with ServedRig("dynamixel", None, flags=["--no-camera"], log=log) as rig:
        nominal_joint_calibration("safety-follower")
        yield rig


def _teleoperate(follower: ServedRig, *teleop: str) -> tuple[subprocess.Popen[str], list[str]]:
    """lerobot-teleoperate for two minutes in the background, once its loop runs; its output
    is gathered in the list returned."""
    cmd = [
        str(BIN / "lerobot-teleoperate"), "--robot.type=ergo_jr_dynamixel",
        bus_flag(follower, "robot"), "--robot.id=safety-follower", *teleop,
        "--teleop_time_s=120",
    ]  # fmt: skip
    proc = subprocess.Popen(
        cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        text=True, env={**os.environ}, start_new_session=True,
    )  # fmt: skip
    out: list[str] = []
    deadline = time.monotonic() + LOOP_BOUND_S
    assert proc.stdout is not None
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        out.append(line)
        if "Teleop loop time" in line:
            import threading

            threading.Thread(target=lambda: out.extend(proc.stdout), daemon=True).start()
            return proc, out
    proc.kill()
    raise AssertionError(f"lerobot-teleoperate never looped: {''.join(out)[-3000:]}")


def _torque_is_on(rig: ServedRig) -> bool:
    """Whether the served twin's servos hold their torque, asked of its hands (a hand cannot
    move a powered joint), without touching the bus the script uses."""
    owner = Owner(rig, "probe", CALIBRATION)
    with owner.hands() as hands:
        try:
            hands.move({"m6": 0.0})
        except HandsError as exc:
            assert "torque on" in str(exc)
            return True
    return False


@pytest.mark.timeout(900)
@pytest.mark.parametrize("how", ["SIGINT", "SIGKILL"])
def test_torque_goes_off_when_the_script_is_interrupted_or_killed(follower, how):
    t0 = time.monotonic()
    proc, out = _teleoperate(follower, "--teleop.type=ergo_jr_scripted")
    assert _torque_is_on(follower)
    os.kill(proc.pid, getattr(signal, how))
    rc = proc.wait(timeout=60)
    note(
        f"lerobot-teleoperate ... --robot.type=ergo_jr_dynamixel, then {how}",
        rc,
        time.monotonic() - t0,
    )
    time.sleep(0.5)  # a killed one: its guardian writes the torque-off (robot.torque_guardian)
    assert Owner(follower, "probe", CALIBRATION).torque_read_back() == [False] * 6
    if how == "SIGINT":
        assert rc == 0, "".join(out)[-3000:]  # LeRobot's teleoperate ends on Ctrl-C as asked


@pytest.mark.timeout(900)
def test_torque_goes_off_when_the_script_ends_on_an_exception(follower, tmp_path):
    nominal_joint_calibration("safety-leader")
    t0 = time.monotonic()
    with ServedRig("dynamixel", None, flags=["--no-camera"], log=tmp_path / "leader.log") as leader:
        teleop = [
            "--teleop.type=ergo_jr_leader",
            bus_flag(leader, "teleop"),
            "--teleop.id=safety-leader",
        ]
        proc, out = _teleoperate(follower, *teleop)
        assert _torque_is_on(follower)
        leader.stop()  # the leader's bus is gone: its reading raises, the script ends
        rc = proc.wait(timeout=120)
    note(
        "lerobot-teleoperate ... --teleop.type=ergo_jr_leader, the leader's bus lost",
        rc,
        time.monotonic() - t0,
    )
    text = "".join(out)
    assert rc != 0 and "Traceback" in text, text[-3000:]
    assert Owner(follower, "probe", CALIBRATION).torque_read_back() == [False] * 6
