"""How well a representation of 64x64 observations explains its images, without labels.

``explained_pixel_variance``: 1 - (squared error of the reconstructions) / (squared error of
the mean training image), over held-out images. The mean image already explains the static
scene (floor, walls, the arm at rest), which dominates any plain reconstruction loss: the
VAE's held-out loss differed by 0.15% between models that located the ball and models that
did not (docs/results.md). What is left after the mean image is what moves, so this ratio is
near 0 for a model whose code carries nothing (a collapsed one reconstructs about the mean
image) and near 1 for one that redraws the moving objects where they are. It looks at images
only, never at the true ball position: a campaign can choose its model by it.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from plumbing.files import atomic_write

HELDOUT = 0.1  # share of a dataset kept out of training to score the model (guess)
SELECTION_FILE = "selection.json"


def explained_pixel_variance(
    reconstruct: Callable[[np.ndarray], np.ndarray],
    heldout: np.ndarray,
    mean_image: np.ndarray,
) -> float:
    """Fraction of the held-out images' variance about ``mean_image`` that the reconstructions
    explain (1 perfect, 0 no better than the mean image, negative worse).

    Args:
        reconstruct: BGR uint8 images (n, H, W, 3) -> their reconstructions, same shape.
        heldout: BGR uint8 images (n, H, W, 3) the model was not trained on.
        mean_image: the training images' mean, (H, W, 3), in grey levels (0..255).
    """
    x = np.asarray(heldout, dtype=np.float64)
    if len(x) == 0:
        raise ValueError("no held-out images to score on")
    rec = np.asarray(reconstruct(heldout), dtype=np.float64)
    if rec.shape != x.shape:
        raise ValueError(f"reconstructions have shape {rec.shape}, images {x.shape}")
    about_mean = float(((x - np.asarray(mean_image, dtype=np.float64)) ** 2).sum())
    if about_mean == 0.0:
        raise ValueError("the held-out images are all the mean image: nothing to explain")
    return 1.0 - float(((x - rec) ** 2).sum()) / about_mean


def heldout_split(n: int, fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(training indices, held-out indices) of ``n`` images, a ``fraction`` held out, by a
    permutation seeded with ``seed``."""
    if not 0.0 <= fraction < 1.0:
        raise ValueError(f"held-out fraction must be in [0, 1), got {fraction}")
    order = np.random.default_rng(seed).permutation(n)
    k = round(n * fraction)
    return np.sort(order[k:]), np.sort(order[:k])


def train_and_select(out: Path, seeds: list[int], train_one: Callable[[int, Path], Any]) -> Any:
    """One seed: ``train_one(seed, out)``. Several: each into ``out/seed-S`` (each resumable),
    then the model with the largest held-out explained pixel variance (a criterion that looks
    at images only, never at the ball's true position) is saved into ``out`` itself, and
    ``out/selection.json`` records every seed's value and the choice. Returns the model."""
    if len(seeds) == 1:
        return train_one(seeds[0], out)
    models = {s: train_one(s, out / f"seed-{s}") for s in seeds}
    scores = {s: float(m.config.heldout_explained_variance) for s, m in models.items()}
    best = max(seeds, key=lambda s: (scores[s], -s))
    models[best].save(out)
    record = {"criterion": "heldout_explained_variance", "scores": scores, "chosen": best}
    atomic_write(out / SELECTION_FILE, json.dumps(record, indent=1))
    for s in seeds:
        print(f"seed {s}: held-out explained pixel variance {scores[s]:.3f}"
              f"{'  <- chosen' if s == best else ''}")  # fmt: skip
    return models[best]
