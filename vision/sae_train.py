"""Training a ``vision.spatial_ae.SpatialAutoencoder``: the VAE's loop (``vae_train.fit``:
seeded batches, checkpoints, resume), a held-out split scored by the selection criterion,
and the code's statistics.

Files in the output folder: ``checkpoint.pt``, ``train_log.csv`` (iteration, loss, recon) and
the final ``sae.pt`` + ``sae.json``.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from vision.representation_quality import HELDOUT, explained_pixel_variance, heldout_split
from vision.spatial_ae import SaeConfig, SpatialAutoencoder
from vision.vae_train import TrainConfig, fit

# Schedule measured on 3000 twin outcome images (docs/results.md): Adam 1e-3, batch 64; the
# code locates the ball (held-out R^2 >= 0.99) by 700 iterations, about 1 CPU minute.
SAE_ITERATIONS = 700


def train_sae(
    images: np.ndarray,
    out: str | Path,
    model_config: SaeConfig | None = None,
    config: TrainConfig | None = None,
    heldout: float = HELDOUT,
    progress: bool = True,
) -> SpatialAutoencoder:
    """Train (or resume) a spatial autoencoder on ``images`` (n, 64, 64, 3) BGR uint8 into
    ``out``: ``heldout`` of them (a split seeded by the training seed) are kept out and score
    the model (``SaeConfig.heldout_explained_variance``). Returns the model, also saved."""
    config = config or TrainConfig(iterations=SAE_ITERATIONS)
    model_config = model_config or SaeConfig()
    images = np.asarray(images)
    train_idx, test_idx = heldout_split(len(images), heldout, config.seed)
    train = images[train_idx]
    settings = model_config.settings()
    mean_rgb = torch.from_numpy(train.mean(axis=0)[..., ::-1] / 255.0).permute(2, 0, 1).float()

    def make(s: dict[str, int]) -> SpatialAutoencoder:
        model = SpatialAutoencoder(SaeConfig(**s))
        model.set_background(mean_rgb)
        return model

    model = fit(make, settings, train, out, config, progress, desc="sae")
    code = model.encode_bgr(train)
    std = code.std(axis=0)
    corr = np.zeros((code.shape[1], code.shape[1]))
    moving = std > 0
    if moving.any():
        corr[np.ix_(moving, moving)] = np.atleast_2d(np.corrcoef(code[:, moving].T))
    stats = {
        "code_mean": code.mean(axis=0).tolist(), "code_std": std.tolist(),
        "code_corr": corr.tolist(),
    }  # fmt: skip
    if len(test_idx):
        mean_image = train.astype(np.float64).mean(axis=0)
        stats["heldout_explained_variance"] = explained_pixel_variance(
            model.reconstruct_bgr, images[test_idx], mean_image
        )
    model.config = replace(model.config, **stats)
    model.save(out)
    return model
