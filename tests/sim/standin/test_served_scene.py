"""The served scene: the plain ``ergo twin serve`` shows the arena's markers and nothing else
changes (the arm's and the ball's physics are the committed scene's to the bit, the ball
tracker sees the ball where it did); a stand-in's frames come through its hidden lens (the
markers' corners land where the hidden camera projects them, not where the nominal one would)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from sim.models.make_scene import ARENA_MARKER_SIZE, ARENA_MARKERS
from sim.standin.hidden import draw_hidden, nominal_camera, nominal_rig
from sim.standin.lens import ServedFrames
from sim.standin.served import served_twin
from sim.twin import Twin
from vision.tracker import BallTracker


def marker_corners(image: np.ndarray) -> dict[int, np.ndarray]:
    """id -> (4, 2) pixels of the arena's markers found in a frame (sub-pixel refined)."""
    dico = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    corners, ids, _ = cv2.aruco.ArucoDetector(dico, params).detectMarkers(
        cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    )
    return (
        {}
        if ids is None
        else {int(i): c.reshape(4, 2) for c, i in zip(corners, ids.ravel(), strict=True)}
    )


def marker_world(marker_id: int) -> np.ndarray:
    """The marker's corners on the floor in ArUco's order, shape (4, 3), metres."""
    x, y = ARENA_MARKERS[marker_id]
    h = ARENA_MARKER_SIZE / 2
    return np.array([[x - h, y + h, 0], [x + h, y + h, 0], [x + h, y - h, 0], [x - h, y - h, 0]])


def test_the_plain_served_twin_moves_as_the_committed_one():
    """The markers, the board and the hands' (inactive) grips change nothing of the physics:
    the same commands give the same trajectories, arm and ball, to the last bit."""
    served, _ = served_twin(nominal_rig())
    committed = Twin()
    try:
        rng = np.random.default_rng(3)
        for twin in (served, committed):
            twin.reset(ball_xy=(0.0, 0.15))
        for _ in range(12):
            targets = rng.uniform(-1.2, 1.2, 6)
            for twin in (served, committed):
                twin.set_targets(targets)
                twin.step(0.25)
            assert np.array_equal(served.joint_positions(), committed.joint_positions())
            assert np.array_equal(served.ball_position(), committed.ball_position())
    finally:
        served.close()
        committed.close()


def test_the_plain_served_camera_shows_the_markers_and_the_ball_as_before():
    from calibration.arena import MarkerLayout, arena_from_markers

    served, plan = served_twin(nominal_rig())
    committed = Twin()
    frames = ServedFrames(served, plan)
    try:
        for twin in (served, committed):
            twin.reset(ball_xy=(-0.1, 0.11))
        image = frames()
        assert image.shape == (240, 240, 3) and plan.maps is None
        camera = nominal_camera()
        found = marker_corners(image)
        assert sorted(found) == [0, 1, 2, 3]
        for i, px in found.items():
            assert np.abs(camera.project(marker_world(i)) - px).max() < 0.5
        # the arena calibration finds its default layout with the nominal camera
        fit = arena_from_markers(image, MarkerLayout(), camera.camera_matrix, np.zeros(5))
        assert fit.points_used == 16 and fit.residuals_mm.max() < 1.0
        assert fit.model.camera_position == pytest.approx([0.0, 0.0, 0.55], abs=0.005)
        # the ball tracker sees the ball where it sees it in the committed scene's frame
        before = BallTracker().track(committed.render())
        after = BallTracker().track(image)
        assert before.seen and after.seen
        assert np.abs(np.subtract(after.pixel, before.pixel)).max() < 0.05
        # and the frames differ only outside the wall (the markers), but for the floor's
        # colour rounded once more in the markers' texture (1 grey level)
        diff = np.abs(image.astype(int) - committed.render()).max(axis=2)
        assert diff.max() > 100  # the markers
        rows, cols = np.nonzero(diff > 2)
        radius = np.hypot(cols - 119.5, rows - 119.5)  # pixels from the arena's centre
        assert radius.min() > 105  # 0.21 m from the centre (the wall's outer face) is 98 px
    finally:
        frames.close()
        served.close()
        committed.close()


@pytest.mark.parametrize("seed", [0, 7])
def test_a_stand_in_frame_comes_through_the_hidden_lens(seed):
    """A known point (each marker's corners on the floor) lands where the hidden camera
    projects it, within a pixel and a half, and tens of pixels from the nominal camera's."""
    rig = draw_hidden(seed)
    twin, plan = served_twin(rig)
    frames = ServedFrames(twin, plan)
    try:
        image = frames()
        assert image.shape == (480, 640, 3)
        found = marker_corners(image)
        assert sorted(found) == [0, 1, 2, 3]
        nominal = nominal_camera((640, 480))
        away = []  # how far the nominal camera would put each corner, px
        for i, px in found.items():
            world = marker_world(i)
            assert np.abs(rig.camera.project(world) - px).max() < 1.5  # measured 0.7-1.1 px
            away += list(np.linalg.norm(nominal.project(world) - px, axis=1))
        assert max(away) > 10
        ball = BallTracker().track(image)
        assert ball.seen
        truth = rig.camera.project(np.array([[*rig.ball_xy, 0.03]]))[0]
        assert np.linalg.norm(np.subtract(ball.pixel, truth)) < 2.0
    finally:
        frames.close()
        twin.close()
