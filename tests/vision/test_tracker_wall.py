"""The tracker finds a ball resting against the arena's wall on a stand-in's camera, where its
outline comes through the JPEG stream with a spur or a flattened side (its edge blended with
the wall's); an arm hiding part of such a ball still gives no wrong position.

The scenes are rendered in one process as ``ergo twin serve --stand-in SEED`` serves them (the
hidden camera's pose and lens, ``sim.standin.lens.ServedFrames``, then JPEG at the stream's
quality); the arena is calibrated from the frame's markers as ``ergo calibrate arena`` does,
with the stand-in's true intrinsics in place of a chessboard calibration (tests may read the
hidden parameters). The places are the two that the enclosing-circle test alone refused when
stand-ins 300-329 were rendered so with the ball against the wall every 3 to 5 degrees; the
served sweep with the guide's calibrations is experiments/tracker_wall.py
(docs/vision.md).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from calibration import arena as ar
from calibration import ball_colour
from sim.mjpeg_server import DEFAULT_JPEG_QUALITY
from sim.models.make_scene import BALL_RADIUS, OUTER_RADIUS
from sim.standin.hidden import draw_hidden
from sim.standin.lens import ServedFrames
from sim.standin.served import served_twin
from vision.rectify import ArenaModel
from vision.tracker import BallTracker, tracker_config_from_arena

TOL_M = 0.005  # the tracker's bound (tests/vision/test_tracker.py)
AT_WALL_M = OUTER_RADIUS - BALL_RADIUS  # the ball's centre touching the wall: 0.17 m
# (stand-in seed, angle of the ball around the base in degrees): the enclosing circle's
# circularity 0.79 and 0.81 there, below the 0.85 gate (measured).
AT_WALL = [(321, 171.0), (329, 9.0)]
# The tool tip 1 cm above a ball at (0.17, 0) m (at its centre and 2 cm off it radially and
# sideways), m1 m2 m3 m5 in rad (m4 = m6 = 0): least squares on the nominal twin's kinematics,
# checked below; turned about the base with m1 for another place.
HOVER_TIP_Z = BALL_RADIUS * 2 + 0.013 + 0.01  # the ball's top, the tool's radius, 1 cm
HOVER = [
    ((0.0, 0.0), (0.09, 0.4, 0.359, 1.513)),
    ((0.02, 0.0), (0.08, 0.547, 0.318, 1.309)),
    ((-0.02, 0.0), (0.102, 0.099, 0.652, 1.569)),
    ((0.0, 0.02), (0.206, 0.434, 0.314, 1.522)),
    ((0.0, -0.02), (-0.028, 0.342, 0.466, 1.446)),
]


class Scene:
    """A stand-in's served camera in one process, its arena calibrated from a frame."""

    def __init__(self, seed: int) -> None:
        self.rig = draw_hidden(seed)
        self.twin, plan = served_twin(self.rig)
        self.frames = ServedFrames(self.twin, plan)
        self.pose(np.zeros(6))
        self.twin.place_ball(self.rig.ball_xy)
        image = self.frame()
        cam = self.rig.camera
        fit = ar.arena_from_markers(image, ar.MarkerLayout(), cam.camera_matrix, cam.dist_coeffs)
        pixel = ball_colour.find_saturated_blob(image, fit.model, BALL_RADIUS)
        ranges = ball_colour.sample_ball_hsv(image, pixel)
        self.data = ar.arena_payload(fit, ranges, BALL_RADIUS, "test")

    def tracker(self, **config) -> BallTracker:
        from dataclasses import replace

        base = tracker_config_from_arena(self.data)
        return BallTracker(replace(base, **config), ArenaModel.from_dict(self.data))

    def pose(self, q: np.ndarray) -> None:
        """The arm at joint angles q (6,) rad, kinematically (a still frame)."""
        self.twin.data.qpos[self.twin._qpos_idx] = q
        mujoco.mj_forward(self.twin.model, self.twin.data)

    def frame(self) -> np.ndarray:
        """The served frame, through JPEG as the MJPEG stream sends it: (480, 640, 3) BGR."""
        import cv2

        ok, jpeg = cv2.imencode(
            ".jpg", self.frames(), [cv2.IMWRITE_JPEG_QUALITY, DEFAULT_JPEG_QUALITY]
        )
        assert ok
        return cv2.imdecode(jpeg, cv2.IMREAD_COLOR)

    def close(self) -> None:
        self.frames.close()
        self.twin.close()


@pytest.fixture(scope="module", params=AT_WALL, ids=[f"standin{s}-{a:.0f}deg" for s, a in AT_WALL])
def at_wall(request):
    seed, angle = request.param
    scene = Scene(seed)
    a = math.radians(angle)
    xy = np.array((AT_WALL_M * math.cos(a), AT_WALL_M * math.sin(a)))
    scene.twin.place_ball(tuple(xy))
    yield scene, xy, scene.frame()
    scene.close()


def test_a_ball_against_the_wall_is_found_at_its_place(at_wall):
    scene, xy, image = at_wall
    round_only = scene.tracker(outline_fit=False).track(image)
    assert not round_only.seen and "not round" in round_only.reason  # what was missed
    obs = scene.tracker().track(image)
    assert obs.seen, obs.reason
    assert obs.outline is not None  # found by its outline's circle
    assert np.hypot(*(np.asarray(obs.xy) - xy)) < TOL_M
    assert obs.r == pytest.approx(AT_WALL_M, abs=TOL_M)


def test_the_arm_over_a_ball_at_the_wall_gives_no_wrong_place(at_wall):
    """The tool hovering over the ball's centre or a side: not seen, or seen where it is."""
    scene, xy, _ = at_wall
    tracker = scene.tracker()
    angle = math.atan2(xy[1], xy[0])
    outcomes = []
    try:
        for (dr, ds), (m1, m2, m3, m5) in HOVER:
            scene.pose(np.array([m1 + angle, m2, m3, 0.0, m5, 0.0]))
            radial = np.array((math.cos(angle), math.sin(angle)))
            side = np.array((-math.sin(angle), math.cos(angle)))
            tip = np.array([*(xy + dr * radial + ds * side), HOVER_TIP_Z])
            np.testing.assert_allclose(scene.twin.end_effector_position(), tip, atol=1e-3)
            obs = tracker.track(scene.frame())
            if obs.seen:
                assert np.hypot(*(np.asarray(obs.xy) - xy)) < TOL_M, obs.describe()
            outcomes.append(obs.seen)
    finally:
        scene.pose(np.zeros(6))
    assert not all(outcomes)  # the tool hides enough of the ball at least once


def test_the_arm_is_not_the_ball(at_wall):
    """The ball taken away: the arm over where it was (its orange tool, grey links) is no ball."""
    scene, xy, _ = at_wall
    tracker = scene.tracker()
    angle = math.atan2(xy[1], xy[0])
    scene.twin.place_ball((-0.9, -0.9))  # out of view
    try:
        for _, (m1, m2, m3, m5) in HOVER:
            scene.pose(np.array([m1 + angle, m2, m3, 0.0, m5, 0.0]))
            obs = tracker.track(scene.frame())
            assert not obs.seen, obs.describe()
    finally:
        scene.pose(np.zeros(6))
        scene.twin.place_ball(tuple(xy))
