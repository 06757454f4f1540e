"""The hands on a stand-in twin running in (scaled) real time, in this process: they move a
limp joint and hold it, refuse a powered one, let go when its torque comes on, hold a board
that the served camera (through the stand-in's lens) shows where the hidden camera says; and
their protocol answers bad requests in one line.

No assertion is on durations: the hands wait on simulated time."""

from __future__ import annotations

import json
import socket
import time
from collections.abc import Iterator

import cv2
import numpy as np
import pytest

from robot.spec import ERGO_JR_JOINTS
from sim.realtime import RealtimeLoop
from sim.standin.board import BoardGeometry
from sim.standin.hands import MAX_HAND_SPEED_RAD_S, Hands, HandsError, HandsServer, board_to_world
from sim.standin.hands_client import HandsClient
from sim.standin.hidden import draw_hidden
from sim.standin.lens import ServedFrames
from sim.standin.served import served_twin

SEED = 4
CHESSBOARD = {"kind": "chessboard", "squares": [10, 7], "square_m": 0.02}
CHARUCO = {"kind": "charuco", "squares": [7, 5], "square_m": 0.03, "marker_m": 0.022}


@pytest.fixture(scope="module")
def served() -> Iterator[tuple]:
    """(twin, hands, frames, rig, port) of a stand-in twin stepped at twice real time."""
    rig = draw_hidden(SEED)
    twin, plan = served_twin(rig)
    frames = ServedFrames(twin, plan)
    hands = Hands(twin, textures_changed=frames.textures_changed.set)
    try:
        with RealtimeLoop(twin, speed=2.0), HandsServer(hands) as server:
            yield twin, hands, frames, rig, server.port
    finally:
        frames.close()
        twin.close()


@pytest.fixture
def limp(served):
    twin, hands, *_ = served
    twin.set_torque(False)
    yield served
    hands.release()
    hands.status()  # drop the notes
    hands.put_board_away()


def wait_simulated(twin, seconds: float) -> None:
    """Until the twin's clock has advanced by ``seconds`` (bounded: 10000 naps)."""
    end = twin.time + seconds
    for _ in range(10000):
        if twin.time >= end:
            return
        time.sleep(0.005)
    raise AssertionError("the twin's clock stopped")


def index(name: str) -> int:
    return ERGO_JR_JOINTS.index(name)


def test_hands_move_a_limp_joint_hold_it_and_let_go(limp):
    twin, hands, *_ = limp
    reply = hands.move({"m2": 0.6, "m3": -0.4})
    assert reply["held"] == {"m2": 0.6, "m3": -0.4}
    wait_simulated(twin, 0.5)  # half a second later, still held
    q = twin.joint_positions()
    assert abs(np.degrees(q[index("m2")] - 0.6)) < 0.05
    assert abs(np.degrees(q[index("m3")] + 0.4)) < 0.05
    assert "let go of m2, m3" in hands.release()["did"]
    wait_simulated(twin, 1.0)
    # let go, the arm leaning forward falls under its own weight
    assert abs(twin.joint_positions()[index("m2")] - 0.6) > np.radians(2)


def test_a_quicker_hand_gets_there_sooner_and_holds_as_well(limp):
    twin, hands, *_ = limp
    t0 = twin.time
    hands.move({"m3": -0.9})  # 0.9 rad at the careful 1 rad/s
    careful = twin.time - t0
    t0 = twin.time
    hands.move({"m3": 0.9}, speed=MAX_HAND_SPEED_RAD_S)  # 1.8 rad back, six times as fast
    quick = twin.time - t0
    assert quick < careful, (quick, careful)
    wait_simulated(twin, 0.5)  # held as a careful hand holds it
    assert abs(np.degrees(twin.joint_positions()[index("m3")] - 0.9)) < 0.05
    for bad in (0, -1.0, MAX_HAND_SPEED_RAD_S * 1.01, "fast", True, float("nan")):
        message = hands.handle({"cmd": "move", "joints": {"m3": 0.0}, "speed": bad})["error"]
        assert message.startswith("move: speed must be a number") and "\n" not in message


def test_a_powered_joint_is_refused_in_one_line(limp):
    twin, hands, *_ = limp
    mask = np.zeros(6, bool)
    mask[index("m3")] = True
    twin.set_joint_torque(mask)
    with pytest.raises(HandsError) as info:
        hands.move({"m2": 0.3, "m3": 0.3})
    message = str(info.value)
    assert "\n" not in message and message.startswith("m3 has torque on")
    assert hands.held() == {}  # nothing was gripped
    assert hands.move({"m2": 0.3})["held"] == {"m2": 0.3}  # the limp one is fine


def test_the_hands_put_the_ball_down_where_asked(limp):
    twin, *_, port = limp
    with HandsClient(port) as client:
        assert client.place_ball((-0.1, 0.12))["position"] == [-0.1, 0.12]
    np.testing.assert_allclose(twin.ball_position()[:2], (-0.1, 0.12), atol=1e-3)
    assert twin.ball_speed() < 0.05


def test_the_hands_let_go_when_torque_comes_on(limp):
    twin, hands, *_ = limp
    hands.move({"m5": 0.5})
    twin.set_torque(True)
    hands.tick()
    status = hands.status()
    assert status["held"] == {} and status["notes"] == ["let go of m5: its torque came on"]


@pytest.mark.parametrize(
    ("request_", "message"),
    [
        ({"cmd": "move", "joints": {"m7": 0.1}}, "no joint 'm7'"),
        ({"cmd": "move", "joints": {"m3": 2.0}}, "m3: 2.000 rad is past its stop"),
        ({"cmd": "move", "joints": {"m3": "up"}}, "m3: angle must be a number"),
        ({"cmd": "move", "joints": {}}, 'move needs "joints"'),
        ({"cmd": "wave"}, "unknown cmd 'wave'"),
        ({"cmd": "status", "loud": True}, "status: unknown field(s) loud"),
        ({"cmd": "board", "board": CHESSBOARD}, 'board needs "board"'),
        ({"cmd": "board", "board": {**CHESSBOARD, "square_m": -1}, "position": [0, 0, 0.3]},
         "square_m must be a number > 0"),
        ({"cmd": "board", "board": {**CHARUCO, "marker_m": 0.04}, "position": [0, 0, 0.3]},
         "marker_m 0.04 must be smaller"),
        ({"cmd": "board", "board": {**CHARUCO, "dictionary": "DICT_NOPE"}, "position": [0, 0, 1]},
         "'DICT_NOPE' is not a cv2.aruco dictionary"),
        ({"cmd": "board", "board": CHESSBOARD, "position": [0, 0, -0.1]}, "above the floor"),
        ({"cmd": "board", "board": CHESSBOARD, "position": [0, 0]}, "three finite numbers"),
        ({"cmd": "board", "board": CHESSBOARD, "position": [0, 0, 1e300]}, "reaches 1.5 m"),
        ({"cmd": "board", "board": CHESSBOARD, "position": [0, 0, 0.3],
          "euler_deg": [1e300, 0, 0]}, "within +-360 deg"),
        ({"cmd": "board", "board": {**CHESSBOARD, "square_m": 1e-300}, "position": [0, 0, 0.3]},
         "square_m 1e-300: must be in [0.002, 0.2] m"),
        ({"cmd": "release", "joints": "m1"}, "must be a list"),
        ({"cmd": "ball", "position": [0.3, 0.0]}, "outside the wall"),
        ({"cmd": "ball", "position": [0.1]}, "two finite numbers"),
        ([1, 2], "a request is a JSON object"),
    ],
)  # fmt: skip
def test_bad_requests_are_one_line(limp, request_, message):
    *_, port = limp
    with socket.create_connection(("127.0.0.1", port), timeout=30) as sock:
        f = sock.makefile("rwb")
        f.write((json.dumps(request_) + "\n").encode())
        f.flush()
        reply = json.loads(f.readline())
    assert reply["ok"] is False and message in reply["error"], reply
    assert "\n" not in reply["error"]


def test_the_client_over_the_wire_and_a_line_that_is_not_json(limp):
    *_, port = limp
    with socket.create_connection(("127.0.0.1", port), timeout=30) as sock:
        f = sock.makefile("rwb")
        f.write(b"{not json\n")
        f.flush()
        assert "not JSON" in json.loads(f.readline())["error"]
        f.write(b'{"cmd": "status"}\n')  # the connection still answers
        f.flush()
        assert json.loads(f.readline())["ok"] is True
    with HandsClient(port) as client:
        assert client.move({"m6": -0.5})["held"] == {"m6": -0.5}
        assert client.status()["held"] == {"m6": -0.5}
        with pytest.raises(HandsError, match="no joint"):
            client.release(["m9"])
        assert client.release()["held"] == {}
    with pytest.raises(HandsError, match=r"no hands on 127\.0\.0\.1:1"):
        HandsClient(1)


def detect(board: dict, image: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """(board coordinates (N, 2), pixels (N, 2)) of the board's corners found by OpenCV."""
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    geometry = BoardGeometry.from_dict(board)
    if geometry.kind == "chessboard":
        cols, rows = geometry.squares
        found, corners = cv2.findChessboardCornersSB(grey, (cols - 1, rows - 1))
        if not found:
            return None
        return geometry.object_corners(), corners.reshape(-1, 2)
    dico = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, geometry.dictionary))
    charuco = cv2.aruco.CharucoBoard(geometry.squares, geometry.square_m, geometry.marker_m, dico)
    corners, ids, _, _ = cv2.aruco.CharucoDetector(charuco).detectBoard(grey)
    if ids is None or len(ids) < 6:
        return None
    return geometry.object_corners()[ids.ravel()], corners.reshape(-1, 2)


@pytest.mark.parametrize(
    ("board", "position", "euler_deg"),
    [
        (CHESSBOARD, (0.02, -0.03, 0.36), (0.0, 0.0, 0.0)),
        (CHESSBOARD, (-0.04, 0.02, 0.33), (20.0, -10.0, 30.0)),
        (CHARUCO, (0.0, 0.02, 0.34), (-15.0, 15.0, -20.0)),
    ],
)
def test_a_held_board_is_seen_where_the_hidden_camera_says(limp, board, position, euler_deg):
    """The board in the served frame (the stand-in's lens), found by OpenCV, its corners
    within 1.5 px of the hidden camera's projection of where the hands hold them (and far from
    where the nominal camera would put them); put away, it is gone."""
    _, hands, frames, rig, _ = limp
    hands.move({"m2": 1.2, "m3": 1.0})  # the arm out of the board's way
    reply = hands.show_board(board, position, euler_deg)
    assert reply["position"] == pytest.approx(list(position))
    found = detect(board, frames())
    assert found is not None, f"no {board['kind']} in the served frame"
    obj, px = found
    world = board_to_world(BoardGeometry.from_dict(board), position, euler_deg, obj)
    expected = rig.camera.project(world)
    error = np.linalg.norm(expected - px, axis=1).max()
    if board["kind"] == "chessboard":  # OpenCV may list a chessboard's corners from either end
        error = min(error, np.linalg.norm(expected[::-1] - px, axis=1).max())
    assert error < 1.5, error
    from sim.standin.hidden import nominal_camera

    nominal = nominal_camera((640, 480))
    shift = np.linalg.norm(nominal.project(world) - expected, axis=1)
    assert shift.max() > 10
    assert "put the board away" in hands.put_board_away()["did"]
    assert detect(board, frames()) is None
