"""End to end: ``ergo twin serve --bus {dynamixel,canopen} --stand-in SEED`` in a subprocess,
driven over its pty by the project's own bus classes and by its hands: the raw positions on
both buses follow the hidden offsets and directions (read back from the hidden file), a hand
moves limp joints and is refused a powered one, the fault flags still work, and a bad seed is
one line.

No assertion is on durations: waits are bounded by counts or generous bounds against hangs."""

from __future__ import annotations

import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from robot.errors import SafetyStop
from robot.spec import ERGO_JR_JOINTS
from sim.standin.board import BoardGeometry
from sim.standin.hands import HandsError, board_to_world
from sim.standin.hands_client import HandsClient
from testkit.standin_owner import ServedRig
from testkit.standin_truth import read_hidden

ROOT = Path(__file__).resolve().parents[3]
ERGO_SERVE = [sys.executable, "-m", "explore.cli", "twin", "serve"]
START_BOUND_S = 60.0  # against hangs (the server imports MuJoCo, draws its floor), not a target
POSES = (
    {"m1": 0.4, "m2": 0.5, "m3": -0.6, "m4": -0.3, "m5": 0.7, "m6": -0.4},
    {"m1": -0.5, "m2": -0.3, "m3": 0.4, "m4": 0.6, "m5": -0.5, "m6": 0.3},
)

pytestmark = pytest.mark.slow


@contextmanager
def serve(bus: str, seed: int, hidden: Path, *flags: str) -> Iterator[dict[str, str]]:
    """``ergo twin serve --bus BUS --stand-in SEED --hidden HIDDEN FLAGS``
    (``testkit.standin_owner.ServedRig``); yields its announced lines by their first words
    (``bus``, ``camera``, ``hands``, ``stand-in``); stops it with SIGTERM and expects exit
    code 0."""
    rig = ServedRig(bus, seed, hidden, flags=flags)
    with rig:
        yield rig.lines
    assert rig.proc.returncode == 0


def hands_port(lines: dict[str, str]) -> int:
    return int(lines["hands"].rsplit(":", 1)[1])


def hidden_of(lines: dict[str, str]):
    return read_hidden(lines["stand-in"].split(" in ", 1)[1].split(" (")[0])


def chessboard_corners(stream_url: str, squares: list[int]) -> np.ndarray | None:
    """The inner corners (N, 2) of a chessboard in the served camera's latest frame, or None."""
    import cv2

    url = stream_url.replace("/stream.mjpg", "/snapshot.jpg")
    with urllib.request.urlopen(url, timeout=10) as reply:
        jpeg = np.frombuffer(reply.read(), np.uint8)
    grey = cv2.imdecode(jpeg, cv2.IMREAD_GRAYSCALE)
    found, corners = cv2.findChessboardCornersSB(grey, (squares[0] - 1, squares[1] - 1))
    return corners.reshape(-1, 2) if found else None


def expected_servo_angles(hidden, pose: dict[str, float]) -> np.ndarray:
    q = np.array([pose[j] for j in ERGO_JR_JOINTS])
    return hidden.directions * q + hidden.offsets


def test_dynamixel_raw_positions_follow_the_hidden_mounting(tmp_path):
    from robot.dynamixel.arm import DynamixelArm
    from robot.dynamixel.bus import DynamixelBus

    flags = ["--overload-servo", "6", "--overload-after", "1.0"]  # the fault flags still work
    with (
        serve("dynamixel", 21, tmp_path / "h.json", *flags) as lines,
        HandsClient(hands_port(lines)) as hands,
    ):
        port = lines["bus"].split()[-1]
        hidden = hidden_of(lines)
        assert hidden.seed == 21
        assert lines["camera"].startswith("camera on http://127.0.0.1:")
        # the raw register, in steps, as a host reads it (servo 1..6 = m1..m6)
        with DynamixelBus(port, latency_s=0.05, retries=5) as bus:
            for pose in POSES:
                hands.move(pose)
                steps = np.array([bus.read_register(i, "position") for i in range(1, 7)])
                expected = 512 + expected_servo_angles(hidden, pose) / np.radians(300 / 1023)
                assert np.abs(steps - expected).max() <= 1.0, (steps, expected)
        # the board held up in the served stream (JPEG), where the hidden camera puts it
        board = {"kind": "chessboard", "squares": [9, 7], "square_m": 0.02}
        held = ((0.01, 0.02, 0.35), (15.0, -10.0, 20.0))
        hands.show_board(board, *held)
        found = None
        for _ in range(50):  # bounded: the camera makes its renderer again for the new image
            found = chessboard_corners(lines["camera"].split()[-1], board["squares"])
            if found is not None:
                break
            time.sleep(0.1)
        assert found is not None, "no chessboard in the served stream"
        geometry = BoardGeometry.from_dict(board)
        world = board_to_world(geometry, *held, geometry.object_corners())
        expected = hidden.camera.project(world)
        error = min(  # OpenCV may list a chessboard's corners from either end
            np.linalg.norm(expected - found, axis=1).max(),
            np.linalg.norm(expected[::-1] - found, axis=1).max(),
        )
        assert error < 2.0, error
        hands.put_board_away()
        # an arm that knows nothing of the mounting reads the servos' angles
        with DynamixelArm(port, latency_s=0.05, retries=5) as arm:
            servo = arm.read().positions
            assert np.abs(servo - expected_servo_angles(hidden, POSES[-1])).max() < 0.006
            arm.set_torque(True)
            with pytest.raises(
                HandsError, match=r"^m2 has torque on: a hand cannot move a powered joint"
            ):
                hands.move({"m2": 0.0})
            assert len(hands.status()["notes"]) == 6  # the hands let go when torque came on
            with pytest.raises(SafetyStop, match="overload"):
                for _ in range(400):  # bounded; the overload trips after 1 s of torque
                    arm.read()
                    time.sleep(0.01)


def test_canopen_raw_positions_follow_the_hidden_mounting(tmp_path):
    from robot.canopen.arm import CanArm, config_for

    flags = ["--no-camera", "--overload-servo", "2", "--overload-after", "1.0"]
    with (
        serve("canopen", 22, tmp_path / "h.json", *flags) as lines,
        HandsClient(hands_port(lines)) as hands,
    ):
        hidden = hidden_of(lines)
        assert "camera" not in lines
        # the pty rig's settings, as ergo explore takes them (tests/sim/canopen/test_server.py)
        address = f"slcan:{lines['bus'].split()[-1]}"
        with CanArm(address, config=config_for(address, pdo_timeout_s=0.05)) as arm:
            for pose in POSES:
                hands.move(pose)
                arm.read()  # a fresh SYNC's positions
                counts = arm.read().positions  # counts x 2 pi / 65536: the drive's own angle
                assert np.abs(counts - expected_servo_angles(hidden, pose)).max() < 1e-3
            arm.set_torque(True)
            with pytest.raises(HandsError, match=r"^m3 has torque on"):
                hands.move({"m3": 0.0})
            with pytest.raises(SafetyStop, match="node 2"):
                for _ in range(400):  # bounded; the following error trips after 1 s enabled
                    arm.read()
                    time.sleep(0.01)


def test_a_bad_seed_is_one_line():
    proc = subprocess.run(
        [*ERGO_SERVE, "--bus", "dynamixel", "--stand-in", "-3", "--no-camera"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=START_BOUND_S,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip() == "ergo: error: --stand-in seed must be an integer >= 0, got -3"
