"""The ball's outline circle (``vision.ball_outline``) and the tracker's use of it, on drawn
discs under an ideal camera straight above the arena: a disc with a spur or a side cut off by a
straight edge is found at its true centre; blobs that are not one ball of the expected size (two
balls touching, a disc of the wrong size, a half disc) are still refused."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from vision.ball_outline import fit_outline, kasa_circle, widest_gap_deg
from vision.rectify import ArenaModel
from vision.tracker import BallTracker, TrackerConfig

SIZE = (480, 640)  # (height, width)
F_PX, HEIGHT_M = 530.0, 0.55  # an ideal camera 0.55 m above the floor (the twin's height)
BGR = (0, 220, 200)  # yellow-green: inside the tracker's default range
SCALE = 16  # drawn at 1/16 px (cv2's shift) so that a disc's centre need not be a pixel's


def overhead() -> ArenaModel:
    cx, cy = (SIZE[1] - 1) / 2, (SIZE[0] - 1) / 2
    k = np.array([[F_PX, 0.0, cx], [0.0, F_PX, cy], [0.0, 0.0, 1.0]])
    m = HEIGHT_M / F_PX  # metres a pixel on the floor
    homography = np.array([[m, 0.0, -cx * m], [0.0, -m, cy * m], [0.0, 0.0, 1.0]])
    return ArenaModel(k, np.zeros(5), SIZE[::-1], homography, np.zeros(2), 0.2, (0, 0, HEIGHT_M))


@pytest.fixture(scope="module")
def tracker() -> BallTracker:
    return BallTracker(arena=overhead())


def disc(image: np.ndarray, centre: tuple[float, float], radius: float) -> None:
    c = tuple(round(v * SCALE) for v in centre)
    cv2.circle(image, c, round(radius * SCALE), BGR, -1, cv2.LINE_8, shift=4)


def place(tracker: BallTracker, xy: tuple[float, float]) -> tuple[np.ndarray, float]:
    """The pixel of a ball at ``xy`` m on the arena and its expected radius there, px."""
    from vision.rectify import arena_to_pixels

    px = arena_to_pixels(tracker.arena, np.array(xy), height=tracker.config.ball_radius_m)[0]
    return px, tracker.expected_radius_at(tuple(px))


def test_kasa_circle_and_gaps():
    a = np.linspace(0, 1.5 * math.pi, 40)
    pts = np.column_stack([3 + 10 * np.cos(a), -2 + 10 * np.sin(a)])
    centre, radius = kasa_circle(pts)
    np.testing.assert_allclose(centre, (3, -2), atol=1e-9)
    assert radius == pytest.approx(10)
    assert widest_gap_deg(a) == pytest.approx(90)  # from 270 deg round to 360
    assert widest_gap_deg(np.zeros(0)) == 360


def test_a_whole_disc_keeps_its_centroid(tracker):
    """A round blob takes the old path: the centroid, no outline fit."""
    px, r = place(tracker, (0.16, 0.05))
    image = np.zeros((*SIZE, 3), np.uint8)
    disc(image, px, r)
    obs = tracker.track(image)
    assert obs.seen and obs.outline is None
    assert np.hypot(*(np.asarray(obs.xy) - (0.16, 0.05))) < 0.001


@pytest.mark.parametrize("cut", [0.42, 0.46])
def test_a_disc_cut_by_a_straight_edge_is_found_at_its_centre(tracker, cut):
    """A side cut off (a chord ``cut`` radii deep: 15 % and 17 % of the disc hidden, the
    circularity under 0.85): the centroid moves inward, the outline's circle stays."""
    xy = (-0.12, 0.12)
    px, r = place(tracker, xy)
    image = np.zeros((*SIZE, 3), np.uint8)
    disc(image, px, r)
    outward = np.array(xy) / np.hypot(*xy) * (1, -1)  # image v grows downwards
    rows, cols = np.mgrid[: SIZE[0], : SIZE[1]]
    beyond = (cols - px[0]) * outward[0] + (rows - px[1]) * outward[1] > (1 - cut) * r
    image[beyond] = 0
    round_only = BallTracker(TrackerConfig(outline_fit=False), tracker.arena).track(image)
    assert not round_only.seen
    obs = tracker.track(image)
    assert obs.seen and obs.outline is not None, obs.reason
    assert np.hypot(*(np.asarray(obs.xy) - xy)) < 0.0015
    centroid = tracker.blobs(tracker.mask(image))[0].centroid
    assert np.hypot(*(np.asarray(centroid) - px)) > np.hypot(*(np.asarray(obs.pixel) - px))


def test_a_disc_with_a_spur_is_found_at_its_centre(tracker):
    """A thin ball-coloured spur from its edge (a wall's edge blended with the ball's colour)."""
    xy = (0.0, -0.17)
    px, r = place(tracker, xy)
    image = np.zeros((*SIZE, 3), np.uint8)
    disc(image, px, r)
    spur(image, px, r)
    round_only = BallTracker(TrackerConfig(outline_fit=False), tracker.arena).track(image)
    assert not round_only.seen and "not round" in round_only.reason
    obs = tracker.track(image)
    assert obs.seen, obs.reason
    assert np.hypot(*(np.asarray(obs.xy) - xy)) < 0.0015


def spur(image: np.ndarray, px: np.ndarray, r: float) -> None:
    """A thin ball-coloured spur from the edge of a disc at ``px`` of radius ``r``: the blob is
    no longer round (its enclosing circle grows)."""
    u, v = (round(c) for c in px)
    cv2.line(image, (u + round(0.6 * r), v), (u + round(r + 8), v - 6), BGR, 3)


@pytest.mark.parametrize(
    ("what", "draw"),
    [
        (
            "two balls touching",
            lambda im, px, r: [disc(im, px, r), disc(im, px + np.array((2 * r, 0.0)), r)],
        ),
        (
            "a disc 0.8 of the ball's size",
            lambda im, px, r: [disc(im, px, 0.8 * r), spur(im, px, 0.8 * r)],
        ),
        (
            "a disc 1.2 of the ball's size",
            lambda im, px, r: [disc(im, px, 1.2 * r), spur(im, px, 1.2 * r)],
        ),
    ],
)
def test_blobs_that_are_not_one_ball_are_refused(tracker, what, draw):
    """Blobs the enclosing-circle test refuses and the outline's circle must refuse too."""
    px, r = place(tracker, (0.05, 0.14))
    image = np.zeros((*SIZE, 3), np.uint8)
    draw(image, np.asarray(px), r)
    obs = tracker.track(image)
    assert not obs.seen, f"{what}: {obs.describe()}"
    assert "not round" in obs.reason, obs.reason


def test_a_half_disc_is_refused(tracker):
    """Half a ball (under the arm): its outline goes half round; no position."""
    px, r = place(tracker, (0.15, 0.0))
    image = np.zeros((*SIZE, 3), np.uint8)
    disc(image, px, r)
    image[:, : round(px[0])] = 0
    obs = tracker.track(image)
    assert not obs.seen and "not round" in obs.reason, obs.reason
    assert "deg round" in obs.reason or "fills" in obs.reason


def test_without_an_arena_the_old_decision_holds():
    """No expected size without an arena model: a blob that is not round is refused."""
    tracker = BallTracker()
    image = np.zeros((*SIZE, 3), np.uint8)
    disc(image, (300.0, 200.0), 28.0)
    spur(image, np.array((300.0, 200.0)), 28.0)
    obs = tracker.track(image)
    assert not obs.seen and "no outline fit without an arena model" in obs.reason


def test_fit_outline_needs_three_points_on_a_circle():
    blob = np.ones((3, 3), bool)
    assert fit_outline(np.array([[0.0, 0.0], [1.0, 0.0]]), blob, (0, 0), (0.5, 0.0), 10.0) is None
