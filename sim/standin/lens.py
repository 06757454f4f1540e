"""The served camera's frames: the twin rendered from the camera's pose, then bent by its lens.

MuJoCo renders an ideal pinhole camera with square pixels and the principal point at the
image's centre. A real camera has its own focal lengths, an off-centre principal point and a
distorted lens. ``render_plan`` picks an ideal render (MuJoCo's ``fovy`` and size) that covers
everything the real camera sees at about its resolution; ``ServedFrames`` renders it and remaps
it (``sim.camera.distortion_maps``) so that every served pixel shows what the real lens puts
there. The nominal camera (ideal, centred) is rendered directly.

Units: pixels (OpenCV's convention: pixel centres at integers), degrees for ``fovy``.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import numpy as np

from sim.camera import distortion_maps, ideal_camera_matrix
from sim.mjpeg_server import TwinFrames
from sim.standin.hidden import HiddenCamera
from sim.twin import Twin

# Extra render pixels beyond the farthest point the lens sees, per side (bilinear sampling
# needs one; two for safety).
RENDER_MARGIN_PX = 2


@dataclass(frozen=True)
class RenderPlan:
    """How to make the served frames of a camera.

    Attributes:
        size: (height, width) of MuJoCo's render, pixels.
        fovy_deg: the render's vertical field of view (the MJCF camera's ``fovy``), degrees.
        maps: remap tables from served pixels to render pixels, each (h, w) float32; None when
            the render is the served frame.
    """

    size: tuple[int, int]
    fovy_deg: float
    maps: tuple[np.ndarray, np.ndarray] | None


def _is_ideal(camera: HiddenCamera) -> tuple[bool, float]:
    """(whether MuJoCo renders this camera as it is, its fovy in degrees if so)."""
    w, h = camera.size
    k = camera.camera_matrix
    fovy = math.degrees(2 * math.atan((h / 2) / k[1, 1]))
    ideal = ideal_camera_matrix(fovy, (h, w))
    return bool(not np.any(camera.dist_coeffs) and np.allclose(k, ideal, atol=1e-9)), fovy


def render_plan(camera: HiddenCamera) -> RenderPlan:
    """The render that covers ``camera``'s view at its vertical focal length."""
    ideal, fovy = _is_ideal(camera)
    w, h = camera.size
    if ideal:
        return RenderPlan((h, w), fovy, None)
    import cv2

    k, dist = camera.camera_matrix, camera.dist_coeffs
    u = np.arange(w, dtype=np.float64)
    v = np.arange(h, dtype=np.float64)
    border = np.concatenate(
        [
            np.column_stack([u, np.zeros(w)]),
            np.column_stack([u, np.full(w, h - 1.0)]),
            np.column_stack([np.zeros(h), v]),
            np.column_stack([np.full(h, w - 1.0), v]),
        ]
    ).reshape(-1, 1, 2)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
    normal = cv2.undistortPoints(border, k, dist, None, None, None, criteria).reshape(-1, 2)
    f = float(k[1, 1])
    half_w = math.ceil(np.abs(normal[:, 0]).max() * f) + RENDER_MARGIN_PX
    half_h = math.ceil(np.abs(normal[:, 1]).max() * f) + RENDER_MARGIN_PX
    size = (2 * half_h + 1, 2 * half_w + 1)  # odd: the centre is a pixel, (n - 1) / 2
    fovy_r = math.degrees(2 * math.atan((size[0] / 2) / f))
    render_matrix = ideal_camera_matrix(fovy_r, size)
    return RenderPlan(size, fovy_r, distortion_maps(k, dist, (h, w), render_matrix))


class ServedFrames(TwinFrames):
    """``grab()`` for ``sim.mjpeg_server.MjpegServer``: the twin's overhead camera as the served
    camera sees it, with a renderer of its own (one producer thread, as ``TwinFrames``).

    The renderer is made again after ``textures_changed`` was set (a board's image was drawn
    into the model's texture: MuJoCo uploads textures when a render context is made).

    Args:
        twin: the twin (its overhead camera already at the served pose and ``fovy``).
        plan: from ``render_plan``.
        camera: MJCF camera name.
    """

    def __init__(self, twin: Twin, plan: RenderPlan, camera: str = "overhead") -> None:
        super().__init__(twin, camera, plan.size)
        self.plan = plan
        self.textures_changed = threading.Event()

    def __call__(self) -> np.ndarray:
        """The current served frame, shape (h, w, 3), BGR uint8."""
        import mujoco

        if self.textures_changed.is_set():
            self.close()
        if self._renderer is None:
            with self.twin.lock:  # the context copies the textures: not while they change
                self.textures_changed.clear()
                self._renderer = mujoco.Renderer(self.twin.model, *self.size)
        bgr = super().__call__()
        if self.plan.maps is None:
            return bgr
        import cv2

        return cv2.remap(
            bgr, *self.plan.maps, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
        )
