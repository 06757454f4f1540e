"""Rectification: undistortion round trips, the arena homography, parallax of points above the
floor, the metric top-down image, and the twin's pixels mapped to metres within 5 mm."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim.camera import SimCamera, ideal_camera_matrix, write_marker_scene
from sim.twin import Twin
from vision.rectify import (
    ArenaModel,
    arena_to_pixels,
    distort_points,
    estimate_camera_position,
    fit_homography,
    metres_per_pixel,
    pixels_to_arena,
    polar,
    top_down,
    undistort_image,
    undistort_points,
)

SIZE = (480, 640)
DIST = np.array([-0.25, 0.08, 0.001, -0.0015, 0.0])  # made-up webcam-like distortion
MARKERS = {0: (-0.19, 0.19), 1: (0.19, 0.19), 2: (0.19, -0.19), 3: (-0.19, -0.19)}
MARKER_SIZE = 0.03


def test_undistort_distort_round_trip():
    k = ideal_camera_matrix(45.0, SIZE)
    rng = np.random.default_rng(0)
    px = rng.uniform([0, 0], [SIZE[1] - 1, SIZE[0] - 1], size=(200, 2))
    back = distort_points(undistort_points(px, k, DIST), k, DIST)
    assert np.max(np.abs(back - px)) < 1e-3  # pixels
    assert np.array_equal(undistort_points(px, k, np.zeros(5)), px)


def test_homography_fit_and_shapes():
    h_true = np.array([[0.001, 0.0001, -0.3], [0.00005, -0.001, 0.25], [1e-6, 2e-6, 1.0]])
    px = np.array([[10.0, 20.0], [600.0, 30.0], [620.0, 450.0], [15.0, 470.0], [300, 200]])
    ph = np.column_stack([px, np.ones(5)]) @ h_true.T
    xy = ph[:, :2] / ph[:, 2:]
    h = fit_homography(px, xy)
    np.testing.assert_allclose(h, h_true / h_true[2, 2], rtol=1e-6, atol=1e-9)
    with pytest.raises(ValueError, match=">= 4"):
        fit_homography(px[:3], xy[:3])
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        fit_homography(np.zeros((4, 3)), xy[:4])


def test_polar():
    r, theta = polar(np.array([[0.1, 0.0], [0.0, -0.2], [-0.1, 0.0]]), centre=(0.0, 0.0))
    np.testing.assert_allclose(r, [0.1, 0.2, 0.1])
    np.testing.assert_allclose(theta, [0.0, -math.pi / 2, math.pi])


@pytest.fixture(scope="module")
def marker_twin(tmp_path_factory):
    scene = write_marker_scene(tmp_path_factory.mktemp("scene"), MARKERS, MARKER_SIZE)
    t = Twin(scene=scene, render_size=SIZE)
    yield t
    t.close()


def _model_from_markers(cam: SimCamera, image: np.ndarray) -> ArenaModel:
    """Detect the floor markers in the undistorted frame; fit the homography to their corners."""
    from calibration.arena import MarkerLayout, arena_from_markers

    k, d = cam.intrinsics()
    return arena_from_markers(image, MarkerLayout(MARKERS, MARKER_SIZE), k, d).model


@pytest.mark.parametrize("dist", [None, DIST])
def test_twin_pixels_to_metres_within_5mm(marker_twin, dist):
    cam = SimCamera(marker_twin, size=SIZE, dist_coeffs=dist, noise_std=2.0)
    cam.connect()
    marker_twin.reset()
    model = _model_from_markers(cam, cam.read().image)
    # Floor points all over the arena, projected by the twin's true camera.
    g = np.linspace(-0.2, 0.2, 9)
    xy = np.array([[x, y] for x in g for y in g])
    px = cam.project(np.column_stack([xy, np.zeros(len(xy))]))
    err = np.linalg.norm(pixels_to_arena(model, px) - xy, axis=1)
    assert err.max() < 0.005  # measured: about 0.3 mm
    # Points one ball radius above the floor, using the recovered camera position.
    px_up = cam.project(np.column_stack([xy, np.full(len(xy), 0.03)]))
    err_up = np.linalg.norm(pixels_to_arena(model, px_up, height=0.03) - xy, axis=1)
    assert err_up.max() < 0.005
    # Ignoring the height would be off by up to about r h / H = 0.28 * 0.03 / 0.55 = 15 mm.
    naive = np.linalg.norm(pixels_to_arena(model, px_up) - xy, axis=1)
    assert naive.max() > 0.01
    assert model.camera_position[2] == pytest.approx(0.55, abs=0.005)
    back = arena_to_pixels(model, xy, height=0.03)
    assert np.max(np.linalg.norm(back - px_up, axis=1)) < 0.5  # pixels


def test_camera_position_straight_down():
    """SQPnP + refinement recover a fronto-parallel camera (IPPE did not, on OpenCV 5.0)."""
    k = ideal_camera_matrix(45.0, SIZE)
    xy = np.array([[x, y] for x in (-0.2, 0.0, 0.2) for y in (-0.2, 0.0, 0.2)])
    cam = np.array([0.01, -0.02, 0.55])
    rel = np.column_stack([xy - cam[:2], np.full(len(xy), -cam[2])])
    # OpenCV camera looking down: x right, y down the image (= -y world), z into the floor.
    pc = np.column_stack([rel[:, 0], -rel[:, 1], -rel[:, 2]])
    px = (pc[:, :2] / pc[:, 2:]) * k[0, 0] + k[:2, 2]
    np.testing.assert_allclose(estimate_camera_position(px, xy, k, np.zeros(5)), cam, atol=1e-6)


def test_top_down_image_is_metric(marker_twin):
    import cv2

    cam = SimCamera(marker_twin, size=SIZE, dist_coeffs=DIST)
    cam.connect()
    marker_twin.reset()
    image = cam.read().image
    model = _model_from_markers(cam, image)
    s = 500.0  # px per m
    td = top_down(image, model, px_per_m=s, margin=0.02)
    side = round(2 * 0.22 * s)
    assert td.shape == (side, side, 3)
    corners, ids, _ = cv2.aruco.ArucoDetector(
        cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    ).detectMarkers(td)
    assert ids is not None and sorted(np.asarray(ids).ravel().tolist()) == [0, 1, 2, 3]
    for c, i in zip(corners, np.asarray(ids).ravel(), strict=True):
        x, y = MARKERS[int(i)]
        expected = np.array([(x + 0.22) * s - 0.5, (0.22 - y) * s - 0.5])
        # Within 2 output pixels = 4 mm (the detector's corner bias included).
        assert np.linalg.norm(c.reshape(4, 2).mean(axis=0) - expected) < 2.0
    assert metres_per_pixel(model) == pytest.approx(
        0.55 / ideal_camera_matrix(45, SIZE)[0, 0], rel=0.02
    )


def test_undistort_image_straightens(marker_twin):
    cam = SimCamera(marker_twin, size=SIZE, dist_coeffs=DIST)
    ideal = SimCamera(marker_twin, size=SIZE)
    cam.connect()
    ideal.connect()
    marker_twin.reset()
    k, d = cam.intrinsics()
    und = undistort_image(cam.read().image, k, d).astype(float)
    ref = ideal.read().image.astype(float)
    # Compare the central region (the corners of the undistorted frame have no source pixels).
    sl = (slice(60, 420), slice(80, 560))
    assert np.mean(np.abs(und[sl] - ref[sl])) < 6.0  # grey levels; distorted: far larger
    assert np.mean(np.abs(cam.read().image[sl].astype(float) - ref[sl])) > 2 * np.mean(
        np.abs(und[sl] - ref[sl])
    )


def test_arena_model_round_trip_and_validation():
    k = ideal_camera_matrix(45.0, SIZE)
    m = ArenaModel(k, np.zeros(5), (640, 480), np.eye(3), np.zeros(2), 0.2, np.array([0, 0, 0.5]))
    assert ArenaModel.from_dict(m.to_dict()).to_dict() == m.to_dict()
    with pytest.raises(ValueError, match="radius"):
        ArenaModel(k, np.zeros(5), (640, 480), np.eye(3), np.zeros(2), 0.0)
    with pytest.raises(ValueError, match="camera_position"):
        ArenaModel(k, np.zeros(5), (640, 480), np.eye(3), np.zeros(2), 0.2, np.array([0, 0, -1]))
    flat = ArenaModel(k, np.zeros(5), (640, 480), np.eye(3), np.zeros(2), 0.2)
    with pytest.raises(ValueError, match="camera's position"):
        pixels_to_arena(flat, np.array([[1.0, 2.0]]), height=0.03)
