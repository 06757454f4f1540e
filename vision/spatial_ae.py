"""A deep spatial autoencoder: a representation whose code is where things are in the image.

After Finn, Tan, Duan, Darrell, Levine and Abbeel, "Deep Spatial Autoencoders for Visuomotor
Learning" (ICRA 2016): convolutions produce ``features`` maps; a spatial softmax turns each map
into a distribution over its pixels; the code is the expected image position (x, y) of each
map, ``2 * features`` numbers in [-1, 1] (x right, y down, the image's edges at -1 and 1). A
decoder reconstructs the image from the code alone, so the maps must follow whatever moves.

Two decoders (``SaeConfig.decoder``), both drawing over the mean training image:
- ``"gaussian"`` (default): a gaussian blob at each code position (16 x 16 maps), then
  transposed convolutions, as in keypoint bottlenecks (Jakab, Gupta, Bilen and Vedaldi,
  NeurIPS 2018): a feature is useful only where it sits on the thing it draws, so each follows
  one object all the way. Measured (docs/results.md): on 4 of 4 training seeds every moving
  feature spread over the ball's whole range (std 0.53-0.56), held-out R^2 1.000;
- ``"dense"``: dense layers from the code, Finn et al.'s kind; on 8 seeds R^2 0.950-1.000, but
  many features followed the ball only in part (std 0.1-0.3), and goals drawn in the code's
  bounds then favoured some stretches of the ring (coverage 0.82-0.92 against 0.99).

Why here (docs/results.md, section F2): the paper's VAE folds the ball's position on its ring
into mostly one latent and does so for only some training seeds; a code made of image positions
is, by construction, near for images whose balls are near, whatever the seed.

Images enter as BGR uint8 arrays (n, 64, 64, 3), as the rig stores them. A model is saved as a
folder: ``sae.pt`` (the state dict) and ``sae.json`` (its ``SaeConfig``, with the statistics
measured after training).

This module imports no other package of the project but ``vision``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from vision.vae import (
    VaeError,
    check_statistics,
    few_threads_for,
    load_state,
    read_model_folder,
    to_tensor,
    write_model_folder,
)

FEATURES = 8  # feature maps, a 16-D code (guess, tried: see docs/results.md)
CHANNELS = 16  # convolution channels (guess; 32 trained 4x slower for the same code)
HIDDEN = 256  # decoder's dense layer (guess, the VAE's width)
DECODERS = ("dense", "gaussian")
GAUSS_SIZE = 16  # side of the gaussian decoder's keypoint maps, pixels
GAUSS_SIGMA = 1.5  # their blobs' standard deviation, pixels of that map (6 px of the image)
SHARPNESS = 5.0  # initial multiplier of the standardised maps in the softmax (guess, tried)
MODEL_FILE, CONFIG_FILE = "sae.pt", "sae.json"


@dataclass
class SaeConfig:
    """Architecture, and the statistics measured after training (saved with the weights).

    Attributes:
        features: feature maps; the code has 2 * features numbers.
        channels, hidden: widths of the convolutions and of the dense decoder's layer.
        decoder: ``"gaussian"`` or ``"dense"`` (see the module's docstring).
        code_mean, code_std: mean and standard deviation of each code number over the
            training images (filled after training).
        code_corr: their correlation matrix (2 * features square; 0 for a number that does
            not vary), which tells features that follow the same thing apart from the others.
        heldout_explained_variance: the model-selection criterion on held-out images
            (``explained_pixel_variance``; filled after training when images were held out).
    """

    features: int = FEATURES
    channels: int = CHANNELS
    hidden: int = HIDDEN
    decoder: str = "gaussian"
    code_mean: list[float] | None = field(default=None)
    code_std: list[float] | None = field(default=None)
    code_corr: list[list[float]] | None = field(default=None)
    heldout_explained_variance: float | None = None

    @property
    def code_dim(self) -> int:
        return 2 * self.features

    def validate(self) -> None:
        if self.features < 1 or self.channels < 1 or self.hidden < 1:
            raise VaeError("features, channels and hidden must be positive")
        if self.decoder not in DECODERS:
            raise VaeError(f"decoder must be one of {', '.join(DECODERS)}, got {self.decoder!r}")

    def settings(self) -> dict[str, int | str]:
        """What defines the model (the statistics left out): a checkpoint resumes only with
        the same settings."""
        return {"features": self.features, "channels": self.channels, "hidden": self.hidden,
                "decoder": self.decoder}  # fmt: skip


def spatial_softmax_xy(maps: torch.Tensor, sharpness: torch.Tensor) -> torch.Tensor:
    """Expected image position of each map under a softmax over its pixels.

    Each map is standardised over its pixels first, so that how peaked the softmax is depends
    on ``sharpness`` alone, not on the scale the convolutions happen to start with: with
    random weights a map's most unusual pixels (the ball, on a still scene) already draw its
    expectation to them, and the decoder has a position to learn from at once.

    Args:
        maps: (n, k, h, w) activations.
        sharpness: (k,) positive multipliers of the standardised activations (learned).

    Returns:
        (n, 2k): x_0, y_0, x_1, y_1, ... in [-1, 1] (pixel centres; x right, y down).
    """
    n, k, h, w = maps.shape
    flat = maps.reshape(n, k, h * w)
    z = (flat - flat.mean(dim=-1, keepdim=True)) / (flat.std(dim=-1, keepdim=True) + 1e-5)
    p = F.softmax(z * sharpness.view(1, k, 1), dim=-1)
    p = p.view(n, k, h, w)
    xs = torch.linspace(-1.0, 1.0, w, device=maps.device, dtype=maps.dtype)
    ys = torch.linspace(-1.0, 1.0, h, device=maps.device, dtype=maps.dtype)
    x = (p.sum(dim=2) * xs).sum(dim=-1)  # (n, k)
    y = (p.sum(dim=3) * ys).sum(dim=-1)
    return torch.stack([x, y], dim=-1).reshape(n, 2 * k)


def keypoint_maps(code: torch.Tensor, size: int, sigma: float) -> torch.Tensor:
    """A gaussian blob at each code position: code (n, 2k) in [-1, 1] -> maps (n, k, size,
    size), blobs of standard deviation ``sigma`` pixels of the map."""
    n = code.shape[0]
    xy = code.view(n, -1, 2)
    grid = torch.linspace(-1.0, 1.0, size, device=code.device, dtype=code.dtype)
    s = 2.0 * sigma / (size - 1)  # sigma in [-1, 1] units
    gx = torch.exp(-((grid.view(1, 1, size) - xy[..., :1]) ** 2) / (2 * s * s))  # (n, k, W)
    gy = torch.exp(-((grid.view(1, 1, size) - xy[..., 1:]) ** 2) / (2 * s * s))  # (n, k, H)
    return gy.unsqueeze(-1) * gx.unsqueeze(-2)


class SpatialAutoencoder(nn.Module):
    """Conv features -> spatial softmax -> (x, y) per map; a dense + transposed-conv decoder
    reconstructs the image from the code (Bernoulli logits, as the VAE's)."""

    def __init__(self, config: SaeConfig | None = None) -> None:
        super().__init__()
        self.config = config or SaeConfig()
        self.config.validate()
        c, k, h = self.config.channels, self.config.features, self.config.hidden
        self.encoder = nn.Sequential(
            nn.Conv2d(3, c, 5, 2, 2), nn.ReLU(),  # 64 -> 32
            nn.Conv2d(c, c, 3, 1, 1), nn.ReLU(),
            nn.Conv2d(c, k, 3, 1, 1),
        )  # fmt: skip
        self.log_sharpness = nn.Parameter(torch.full((k,), math.log(SHARPNESS)))
        self.register_buffer("background", torch.zeros(3, 64, 64))
        if self.config.decoder == "dense":
            self.decoder_fc = nn.Sequential(
                nn.Linear(2 * k, h), nn.ReLU(),
                nn.Linear(h, c * 8 * 8), nn.ReLU(),
            )  # fmt: skip
            first = nn.ConvTranspose2d(c, c, 4, 2, 1)  # 8 -> 16
        else:
            self.decoder_fc = None
            first = nn.Conv2d(k, c, 3, 1, 1)  # keypoint maps, 16 x 16
        self.decoder_conv = nn.Sequential(
            first, nn.ReLU(),
            nn.ConvTranspose2d(c, c, 4, 2, 1), nn.ReLU(),  # 16 -> 32
            nn.ConvTranspose2d(c, 3, 4, 2, 1),  # 32 -> 64
        )  # fmt: skip

    def encode(self, x: torch.Tensor) -> torch.Tensor:
        """x (n, 3, 64, 64) in [0, 1] -> code (n, 2 * features) in [-1, 1]."""
        return spatial_softmax_xy(self.encoder(x), self.log_sharpness.exp())

    def decode(self, code: torch.Tensor) -> torch.Tensor:
        """code (n, 2 * features) -> pixel logits (n, 3, 64, 64): the background's logits (the
        training images' mean, ``set_background``) plus what the code draws over it."""
        c = self.config.channels
        if self.decoder_fc is not None:
            return self.background + self.decoder_conv(self.decoder_fc(code).view(-1, c, 8, 8))
        return self.background + self.decoder_conv(keypoint_maps(code, GAUSS_SIZE, GAUSS_SIGMA))

    def set_background(self, mean_rgb: torch.Tensor) -> None:
        """The mean training image, (3, 64, 64) RGB in [0, 1]: the decoder draws over it, so
        from the first iteration the loss is about what moves, not about the static scene."""
        p = mean_rgb.clamp(1e-3, 1 - 1e-3)
        self.background.copy_(torch.log(p) - torch.log1p(-p))

    def loss(self, x: torch.Tensor, iteration: int = 0) -> dict[str, torch.Tensor]:
        """Batch-mean reconstruction (BCE summed over pixels, nats per image): ``loss`` and
        ``recon`` (the same; there is no prior)."""
        recon = F.binary_cross_entropy_with_logits(
            self.decode(self.encode(x)), x, reduction="sum"
        ) / len(x)
        return {"loss": recon, "recon": recon}

    # ---- numpy API ---------------------------------------------------------------------------
    @torch.no_grad()
    def encode_bgr(self, images: np.ndarray, batch: int = 256) -> np.ndarray:
        """Codes of BGR uint8 images (n, 64, 64, 3) -> (n, 2 * features) float64."""
        was = self.training
        if was:  # eval()/train() walk every module (vision/vae.py Vae.encode_bgr)
            self.eval()
        with few_threads_for(len(images)):
            out = [
                self.encode(to_tensor(images[i : i + batch])).double().numpy()
                for i in range(0, len(images), batch)
            ]
        if was:
            self.train(True)
        return np.concatenate(out) if out else np.zeros((0, self.config.code_dim))

    @torch.no_grad()
    def reconstruct_bgr(self, images: np.ndarray, batch: int = 256) -> np.ndarray:
        """Images (n, 64, 64, 3) BGR uint8 -> their reconstructions, same shape and type."""
        was = self.training
        self.eval()
        out = []
        for i in range(0, len(images), batch):
            logits = self.decode(self.encode(to_tensor(images[i : i + batch])))
            rgb = torch.sigmoid(logits).permute(0, 2, 3, 1).numpy()
            out.append((rgb[..., ::-1] * 255.0 + 0.5).astype(np.uint8))
        self.train(was)
        return np.ascontiguousarray(np.concatenate(out)) if out else np.asarray(images).copy()

    # ---- files -------------------------------------------------------------------------------
    def save(self, folder: str | Path) -> Path:
        """Write ``sae.pt`` and ``sae.json`` into ``folder``; returns the folder."""
        return write_model_folder(folder, (MODEL_FILE, CONFIG_FILE), self.state_dict(), self.config)


def is_sae_folder(path: str | Path) -> bool:
    """Whether ``path`` (a folder or its ``sae.pt``) holds a spatial autoencoder."""
    path = Path(path)
    folder = path.parent if path.suffix == ".pt" else path
    return (folder / CONFIG_FILE).is_file()


def load_sae(path: str | Path) -> SpatialAutoencoder:
    """Load a model folder (or its ``sae.pt``) saved by ``SpatialAutoencoder.save``, in eval
    mode."""
    model_file, config_file, raw = read_model_folder(
        path, (MODEL_FILE, CONFIG_FILE), "spatial autoencoder", "ergo sae train"
    )
    try:
        config = SaeConfig(**raw)
        model = SpatialAutoencoder(config)
    except (TypeError, ValueError, RuntimeError) as exc:
        raise VaeError(f"{config_file} is not a spatial autoencoder config: {exc}") from exc
    for name in ("code_mean", "code_std"):
        check_statistics(getattr(config, name), config.code_dim, name, config_file)
    if config.code_corr is not None:
        try:
            corr = np.asarray(config.code_corr, dtype=float)
        except (TypeError, ValueError) as exc:
            raise VaeError(f"{config_file}: code_corr is not a matrix of numbers") from exc
        if corr.shape != (config.code_dim, config.code_dim) or not np.all(np.isfinite(corr)):
            raise VaeError(
                f"{config_file}: code_corr must be {config.code_dim} x {config.code_dim} finite "
                f"numbers, got shape {corr.shape}"
            )
    state = load_state(model_file, "spatial autoencoder model")
    try:
        model.load_state_dict(state)
    except (RuntimeError, KeyError, TypeError, AttributeError) as exc:
        raise VaeError(f"{model_file} does not match its config: {exc}") from exc
    model.eval()
    return model
