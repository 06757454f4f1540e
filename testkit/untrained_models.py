"""Untrained models of the project's learned goal spaces, saved to disk: what a strategy needs
to run when what the representation learnt is not the point (its speed, its plumbing).

Imports torch inside the function, as the rest of ``vision`` does.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def save_untrained_models(root: Path, seed: int = 0) -> dict[str, str]:
    """An untrained VAE, its latents ranked by a made-up KL (9, 8, ..., 0 nats: MGE's modules
    need a ranking), and an untrained spatial autoencoder with made-up code statistics (sd
    0.5, uncorrelated), saved under ``root/vae`` and ``root/sae``. Returns {"vae": path, "sae":
    path}, the strategies' ``vae`` and ``sae`` options."""
    import torch

    from vision.spatial_ae import SaeConfig, SpatialAutoencoder
    from vision.vae import Vae, VaeConfig

    torch.manual_seed(seed)
    vae = Vae(VaeConfig())
    vae.config.kl_per_latent = [float(v) for v in np.arange(vae.config.latent_dim)[::-1]]
    sae = SpatialAutoencoder(SaeConfig())
    k = sae.config.code_dim
    sae.config.code_std, sae.config.code_corr = [0.5] * k, np.eye(k).tolist()
    return {"vae": str(vae.save(root / "vae")), "sae": str(sae.save(root / "sae"))}
