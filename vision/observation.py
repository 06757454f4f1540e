"""The square observation a representation sees: the centre square of a camera frame, reduced
to ``OBSERVATION_SIZE`` pixels a side.

64 x 64 x 3 is the paper's VAE input (Laversanne-Finot et al. 2018; docs/facts.md): the VAE's
architecture is built for it and episodes observe it by default; the size is a run setting
(``explore.runs.config.EpisodeConfig.obs_size``).
"""

from __future__ import annotations

import cv2
import numpy as np

OBSERVATION_SIZE = 64  # side, pixels (the paper)


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
