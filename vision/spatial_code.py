"""What a spatial autoencoder's code says (``vision.spatial_ae``), without torch: which of its
features move. A code is ``2 * features`` numbers, the image position (x, y) of each feature."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

# A feature of a spatial autoencoder whose position moves less than this over the training
# images (standard deviation, in image half-widths) is left out of the goal space: it follows
# something still (measured: such features stay within 0.02 of their mean, those that follow
# the ball spread over 0.3-0.6; docs/results.md). Guess between the two.
LIVE_FEATURE_STD = 0.05


def live_features(code_std: Sequence[float], threshold: float = LIVE_FEATURE_STD) -> list[int]:
    """Indices of the features (pairs of code numbers x, y) whose larger standard deviation
    over the training images reaches ``threshold``; every feature if none does."""
    std = np.asarray(code_std, dtype=float).reshape(-1, 2).max(axis=1)
    live = [int(k) for k in np.flatnonzero(std >= threshold)]
    return live or list(range(len(std)))
