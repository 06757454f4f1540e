"""What a spatial autoencoder's code says (``vision.spatial_ae``), without torch: which of its
features move and follow distinct things. A code is ``2 * features`` numbers, the image
position (x, y) of each feature."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

# A feature of a spatial autoencoder whose position moves less than this over the training
# images (standard deviation, in image half-widths) is left out of the goal space: it follows
# something still or nothing in particular. Measured on the twin's outcome images: features
# that follow the ball or the distractor spread over 0.53-0.56; the others stay within 0.03 of
# their mean with the ball alone and within 0.16 with the distractor, where a few drift with
# whichever ball is near them (docs/results.md). Guess between the two.
LIVE_FEATURE_STD = 0.25
# A live feature whose (x, y) another kept feature's (x, y) predicts linearly with R^2 at
# least this (over the training images) follows the same thing and is left out: one module
# per object, not several copies of the ball. Guess (copies measured at R^2 > 0.999).
SAME_THING_R2 = 0.95


def _r2_of(corr: np.ndarray, target: list[int], given: list[int]) -> float:
    """Smallest R^2 of a linear fit of each code number in ``target`` from those in ``given``,
    from their correlation matrix ``corr``."""
    sub = corr[np.ix_(given, given)]
    return min(float(corr[given, t] @ np.linalg.pinv(sub) @ corr[given, t]) for t in target)


def distinct_features(
    code_std: Sequence[float],
    code_corr: Sequence[Sequence[float]] | None = None,
    threshold: float = LIVE_FEATURE_STD,
    same_r2: float = SAME_THING_R2,
) -> list[int]:
    """The features (pairs x, y of the code) that move (larger standard deviation at least
    ``threshold``) and follow something no feature kept before them follows (``same_r2``),
    taken by decreasing spread; every feature if none moves. Without ``code_corr``, all the
    moving ones. Statistics of the training images only: no label."""
    std = np.asarray(code_std, dtype=float).reshape(-1, 2).max(axis=1)
    moving = [int(k) for k in np.argsort(-std, kind="stable") if std[k] >= threshold]
    if not moving:
        return list(range(len(std)))
    if code_corr is None:
        return sorted(moving)
    corr = np.asarray(code_corr, dtype=float)
    kept: list[int] = []
    for k in moving:
        if all(_r2_of(corr, [2 * k, 2 * k + 1], [2 * j, 2 * j + 1]) < same_r2 for j in kept):
            kept.append(k)
    return sorted(kept)
