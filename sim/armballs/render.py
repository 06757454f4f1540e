"""The observed image of an ArmBalls scene: filled discs on black, drawn with OpenCV (no GL).

As observed in the published campaign (MyArmBallsObserved's observer in the original's
latentgoalexplo/environments/armballs.py, rendered there with gizeh/cairo): a square RGB image,
background black, the ball a yellow disc (RGB 1, 1, 0), the distractor a blue disc (0, 0, 1)
drawn over the ball, the arm not drawn. The square [-1, 1]^2 fills the image: x grows to the
right, and y grows *downwards* (the original hands world y to cairo's row axis unflipped, so
the image is the world seen from below). The original scales the image by its own minimum and
maximum, which for these colours on black is the plain 0..255 range kept here as uint8.

Differences from the original, all below a pixel: cairo's and OpenCV's anti-aliasing differ
at the discs' rims (the discs' areas agree: ``CV_DISC_EXTRA_PX``).
"""

from __future__ import annotations

import cv2
import numpy as np

from sim.armballs.config import ArmBallsConfig
from sim.armballs.kinematics import link_points

BALL_RGB = (255, 255, 0)  # yellow: the original's fill (1, 1, 0)
DISTRACTOR_RGB = (0, 0, 255)  # blue: the original's fill (0, 0, 1)
ARM_RGB = (0, 255, 0)  # green polyline of the original's interactive view (not observed)
ARM_WIDTH_PX = 3  # the original's stroke width, pixels
_SHIFT = 4  # OpenCV fixed-point bits: positions to 1/16 pixel
# OpenCV's filled anti-aliased disc covers about half a pixel more radius than it is asked for
# (measured over 100 discs of radius 4.8 and 5.44 px at random sub-pixel centres: the radius
# of a disc of the image's summed coverage came out 0.536 +- 0.022 px larger); cairo's covers
# the exact area. The radius asked is reduced by this, leaving 0.045 +- 0.016 px.
CV_DISC_EXTRA_PX = 0.5


def pixels_per_unit(size: int) -> float:
    """Image pixels per world unit: the square [-1, 1] spans the image."""
    return size / 2.0


def world_to_pixel(points: np.ndarray, size: int) -> np.ndarray:
    """World (x, y) -> image (column, row), pixel centres at integers.

    The original puts world (0, 0) at cairo coordinate ceil(size / 2) on both axes, where
    cairo's pixel i spans [i, i + 1); here pixel i's centre is i, hence the half pixel.

    Args:
        points: shape (..., 2).
        size: image side, pixels.

    Returns:
        shape (..., 2) float: column (grows with x), row (grows with y).
    """
    p = np.asarray(points, dtype=float)
    return np.ceil(size / 2.0) - 0.5 + p * pixels_per_unit(size)


def pixel_to_world(pixels: np.ndarray, size: int) -> np.ndarray:
    """Inverse of ``world_to_pixel``: (column, row) -> world (x, y), shape (..., 2)."""
    q = np.asarray(pixels, dtype=float)
    return (q - (np.ceil(size / 2.0) - 0.5)) / pixels_per_unit(size)


def _fixed(v: np.ndarray) -> tuple[int, int]:
    f = np.round(np.asarray(v, dtype=float) * (1 << _SHIFT)).astype(np.int64)
    return int(f[0]), int(f[1])


def _disc(img: np.ndarray, centre: np.ndarray, radius: float, rgb: tuple[int, int, int]) -> None:
    size = img.shape[0]
    c = _fixed(world_to_pixel(centre, size))
    r = round(max(radius * pixels_per_unit(size) - CV_DISC_EXTRA_PX, 0.0) * (1 << _SHIFT))
    cv2.circle(img, c, r, rgb, thickness=-1, lineType=cv2.LINE_AA, shift=_SHIFT)


def render_scene(
    ball: np.ndarray,
    distractor: np.ndarray | None = None,
    arm_commands: np.ndarray | None = None,
    config: ArmBallsConfig | None = None,
) -> np.ndarray:
    """Draw one scene.

    Args:
        ball: ball centre (x, y), shape (2,).
        distractor: distractor centre, shape (2,), or None (not drawn).
        arm_commands: joint commands of the pose to draw the arm in, shape (n_joints,), or
            None: the observed images of the published campaign do not show the arm.
        config: sizes; defaults to the published ones.

    Returns:
        shape (image_size, image_size, 3), uint8, RGB.
    """
    cfg = config or ArmBallsConfig()
    size = cfg.image_size
    img = np.zeros((size, size, 3), dtype=np.uint8)
    _disc(img, np.asarray(ball, dtype=float), cfg.ball_draw_radius, BALL_RGB)
    if distractor is not None:
        _disc(img, np.asarray(distractor, dtype=float), cfg.distractor_draw_radius, DISTRACTOR_RGB)
    if arm_commands is not None:
        pts = link_points(np.asarray(arm_commands, dtype=float), np.asarray(cfg.link_lengths))
        pts = np.concatenate([np.zeros((1, 2)), pts], axis=0)
        px = np.round(world_to_pixel(pts, size) * (1 << _SHIFT)).astype(np.int32)
        cv2.polylines(img, [px], False, ARM_RGB, ARM_WIDTH_PX, lineType=cv2.LINE_AA, shift=_SHIFT)
    return img
