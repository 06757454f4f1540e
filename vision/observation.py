"""The square observation a representation sees, reduced to ``OBSERVATION_SIZE`` pixels a side.

Two ways to make it from a camera frame:

- ``square_observation``: the centre square of the frame. On the twin the frame is its
  overhead camera's ideal render, straight above the arena's centre, so the centre square is
  the view (``sim.camera.SimCamera.read_square`` renders it directly).
- ``ArenaObservation``: what a camera anywhere above the arena, with any lens, would give if
  it were that overhead camera (``OverheadView``): for each pixel of the overhead view, the
  point of the arena it shows (on a horizontal plane at a chosen height: the ball's centre's)
  is found in the real frame through the arena calibration (lens, homography, the camera's
  position: ``vision.rectify.arena_to_pixels``), and the frame is sampled there. One model then
  encodes the twin's render and a physical rig's camera alike. Points off that plane (the
  floor, the wall's top, the arm) move by the parallax between the two cameras, under a pixel
  of the 64 px view for a camera within a few centimetres and degrees of the overhead one.
  Measured with stand-in 301's exact calibration: the ball's centroid 0.15 px (median of 20
  ring positions; 0.40 px at most) from where the twin's own render puts it.

64 x 64 x 3 is the paper's VAE input (Laversanne-Finot et al. 2018; docs/facts.md): the VAE's
architecture is built for it and episodes observe it by default; the size is a run setting
(``explore.runs.config.EpisodeConfig.obs_size``).

Pixels: OpenCV's convention (pixel centres at integers); images (H, W, 3) BGR uint8; lengths in
metres, arena frame (x to the overhead image's right, y up it, z up from the floor).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from vision.rectify import ArenaModel

OBSERVATION_SIZE = 64  # side, pixels (the paper)
# The arena view is sampled on a grid this many times finer than the observation, then each
# block of SUPERSAMPLE x SUPERSAMPLE samples averaged into one pixel: the observation's pixel is
# the mean of the frame over the patch of arena it covers (about 7 x 7 camera pixels of a
# 640 x 480 camera at 0.55 m for a 64 px view), not one point of it. 4 is a choice: 16
# samples a pixel. Measured on stand-in 301's camera with its exact calibration, 20 balls on
# the ring: the ball's centroid in the view moves by 0.005 px (median; 0.02 px at most)
# between 4 and 8 samples a side, by 0.10 px (0.34 px) between 1 and 8.
SUPERSAMPLE = 4


def square_observation(frame: np.ndarray, size: int = OBSERVATION_SIZE) -> np.ndarray:
    """Centre square crop of a frame (H, W, 3) resized to (size, size, 3) with area averaging
    (a copy when the crop already has that size)."""
    h, w = frame.shape[:2]
    s = min(h, w)
    y0, x0 = (h - s) // 2, (w - s) // 2
    crop = frame[y0 : y0 + s, x0 : x0 + s]
    if s == size:
        return np.ascontiguousarray(crop).copy()
    return cv2.resize(crop, (size, size), interpolation=cv2.INTER_AREA)


@dataclass(frozen=True)
class OverheadView:
    """An ideal camera straight above the arena, its image's right along +x and its top along +y
    (the twin's overhead camera: ``explore.rigs.ball.TWIN_VIEW`` gives its numbers).

    Attributes:
        height: its optical centre above the floor, m.
        fovy_deg: its field of view across the square image, degrees.
        centre: the point of the floor below it (x, y), m.
    """

    height: float
    fovy_deg: float
    centre: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        if not self.height > 0 or not 0 < self.fovy_deg < 180:
            raise ValueError(
                f"an overhead view needs a height > 0 m and a field of view in (0, 180) deg, got "
                f"{self.height} m and {self.fovy_deg} deg"
            )

    def arena_points(self, side: int, plane_height: float = 0.0) -> np.ndarray:
        """Where each pixel centre of a (side, side) image of this view meets the horizontal
        plane ``plane_height`` m above the floor: shape (side, side, 2), (x, y) m, row 0 at the
        top (largest y). The pinhole of MuJoCo's square render: focal length (side / 2) /
        tan(fovy / 2) px, principal point ((side - 1) / 2, (side - 1) / 2)."""
        if not plane_height < self.height:
            raise ValueError(f"the plane ({plane_height} m) must lie below the view's camera")
        f = (side / 2.0) / math.tan(math.radians(self.fovy_deg) / 2.0)
        c = (side - 1) / 2.0
        depth = self.height - plane_height
        u = (np.arange(side) - c) / f * depth
        x = self.centre[0] + np.broadcast_to(u[None, :], (side, side))
        y = self.centre[1] - np.broadcast_to(u[:, None], (side, side))
        return np.stack([x, y], axis=-1)


class ArenaObservation:
    """A physical camera's frames as ``view`` would show the arena, through an arena
    calibration (module docstring): ``observe(frame, side)`` -> (side, side, 3).

    Args:
        model: the arena calibration (lens, homography, the camera's position).
        view: the overhead view to imitate.
        plane_height: the height of the plane the view is mapped through, m (the ball's
            centre: the ball then sits where the overhead camera would show it). Without the
            camera's position in ``model`` only the floor (0) can be used, and is.
        supersample: samples per pixel along each axis (``SUPERSAMPLE``).

    Parts of the view outside the frame are black. A frame of another size than the
    calibration's (``model.image_size``) is taken as the same camera in another mode: its
    pixels are scaled.
    """

    def __init__(
        self,
        model: ArenaModel,
        view: OverheadView,
        plane_height: float = 0.0,
        supersample: int = SUPERSAMPLE,
    ) -> None:
        if supersample < 1:
            raise ValueError(f"supersample must be at least 1, got {supersample}")
        self.model = model
        self.view = view
        self.plane_height = plane_height if model.camera_position is not None else 0.0
        self.supersample = int(supersample)
        self._maps: dict[tuple[int, int, int], tuple[np.ndarray, np.ndarray]] = {}

    def maps(self, frame_shape: tuple[int, ...], side: int) -> tuple[np.ndarray, np.ndarray]:
        """Remap tables (map_x, map_y), each (side * supersample, side * supersample) float32:
        the raw frame pixel each sample of the view shows (kept per frame size and side)."""
        from vision.rectify import arena_to_pixels

        h, w = int(frame_shape[0]), int(frame_shape[1])
        key = (h, w, side)
        if key not in self._maps:
            fine = side * self.supersample
            xy = self.view.arena_points(fine, self.plane_height).reshape(-1, 2)
            px = arena_to_pixels(self.model, xy, height=self.plane_height)
            width, height = self.model.image_size
            px = px * np.array([w / width, h / height])
            self._maps[key] = (
                px[:, 0].reshape(fine, fine).astype(np.float32),
                px[:, 1].reshape(fine, fine).astype(np.float32),
            )
        return self._maps[key]

    def __call__(self, frame: np.ndarray, side: int = OBSERVATION_SIZE) -> np.ndarray:
        """The view of ``frame`` (H, W, 3) BGR uint8, shape (side, side, 3) uint8."""
        map_x, map_y = self.maps(frame.shape, side)
        fine = cv2.remap(
            frame, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0
        )
        if self.supersample == 1:
            return fine
        return cv2.resize(fine, (side, side), interpolation=cv2.INTER_AREA)
