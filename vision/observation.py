"""The observation a representation sees: a square colour image of ``OBSERVATION_SIZE`` pixels.

64 x 64 x 3, the paper's VAE input (docs/facts.md): episodes reduce the overhead frame to it
(``square_observation``) and the VAE's architecture is built for it.
"""

from __future__ import annotations

import cv2
import numpy as np

OBSERVATION_SIZE = 64  # side, pixels (the paper)


def square_observation(frame: np.ndarray, size: int = OBSERVATION_SIZE) -> np.ndarray:
    """Centre square crop of a frame (H, W, 3) resized to (size, size, 3) with area averaging."""
    h, w = frame.shape[:2]
    s = min(h, w)
    y0, x0 = (h - s) // 2, (w - s) // 2
    crop = frame[y0 : y0 + s, x0 : x0 + s]
    return cv2.resize(crop, (size, size), interpolation=cv2.INTER_AREA)
