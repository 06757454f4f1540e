"""The arena of a served stand-in seen by its camera with the ball put at known places, and the
twin's own render of the same scenes: what experiments/arm_observation.py and
experiments/arm_transfer.py compare (the image a learned goal space sees on the arm against the
twin's; a twin-trained model's code of both).

A person's part is the stand-in's hands' (``testkit.standin_owner.Owner``): they hold the arm
at its rest pose (every joint at zero: where an episode's outcome is observed) and put the ball
down at each place; the camera is read through its MJPEG stream as ``ergo explore --camera URL``
reads it. Nothing here reads the stand-in's hidden parameters.

Places: (n, 2) ball centres on the arena, m; frames (n, H, W, 3) BGR uint8; the twin's renders
(n, side, side, 3) BGR uint8.
"""

from __future__ import annotations

import time

import numpy as np

from robot.spec import ergo_jr_spec
from testkit.standin_owner import Owner

# Wall time between putting the ball down and reading the camera, s: the ball is put down at
# rest and the stream serves about 15 frames a second (guess with a margin: 4 frames).
SETTLE_WALL_S = 0.3
FRESH_FRAMES = 2  # frames read and dropped after a placement (one may predate it)


def hold_at_rest(owner: Owner) -> None:
    """The hands take the limp arm to its rest pose (every joint at zero) and hold it."""
    with owner.hands() as hands:
        hands.move({name: 0.0 for name in ergo_jr_spec().names})


def look_at_places(owner: Owner, places: np.ndarray) -> np.ndarray:
    """The camera's frame with the ball put at each place in turn, the arm held at rest:
    (n, H, W, 3) BGR uint8."""
    from vision.make_camera import make_camera

    hold_at_rest(owner)
    frames = []
    with owner.hands() as hands, make_camera(owner.rig.camera_url, files="live") as camera:
        for xy in np.asarray(places, float):
            hands.place_ball((float(xy[0]), float(xy[1])))
            time.sleep(SETTLE_WALL_S)
            for _ in range(FRESH_FRAMES):
                camera.read()
            frames.append(camera.read().image)
    return np.stack(frames)


def twin_renders(places: np.ndarray, side: int = 64) -> np.ndarray:
    """The committed twin's outcome image with its arm at rest and the ball at each place, as
    a twin episode observes it (``sim.camera.SimCamera.read_square``): (n, side, side, 3)."""
    from sim.camera import SimCamera
    from sim.twin import SCENE, Twin

    twin = Twin(SCENE)
    try:
        camera = SimCamera(twin)
        camera.connect()
        out = []
        for xy in np.asarray(places, float):
            twin.reset((float(xy[0]), float(xy[1])))
            out.append(camera.read_square(side).image)
        return np.stack(out)
    finally:
        twin.close()


def pixel_correlation(a: np.ndarray, b: np.ndarray) -> float:
    """Pearson's correlation of two images' pixel values (every channel), unitless."""
    return float(np.corrcoef(a.ravel().astype(float), b.ravel().astype(float))[0, 1])


def median_image(images: np.ndarray) -> np.ndarray:
    """The per-pixel median of images (n, H, W, 3) uint8: (H, W, 3) uint8."""
    return np.median(images, axis=0).round().astype(np.uint8)


def ball_centroid(image: np.ndarray) -> np.ndarray:
    """The ball's (column, row) in a BGR image (H, W, 3) uint8, px: the centroid of its
    saturated yellow-green pixels (hue 25-50 of OpenCV's 180, the twin's and the stand-ins'
    ball), weighted by saturation above 60 of 255; NaN when there are none."""
    import cv2

    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV).astype(float)
    weight = np.clip((hsv[..., 1] - 60) / 195, 0, 1) * ((hsv[..., 0] > 25) & (hsv[..., 0] < 50))
    if not weight.sum() > 0:
        return np.full(2, np.nan)
    rows, cols = np.mgrid[: image.shape[0], : image.shape[1]]
    return np.array([(weight * cols).sum(), (weight * rows).sum()]) / weight.sum()
