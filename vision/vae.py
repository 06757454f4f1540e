"""The paper's variational autoencoder (VAE / beta-VAE) over 64x64 colour observations.

Architecture (the paper's method section; docs/facts.md): encoder of 4 convolutions of 32
channels, 4x4 kernels, stride 2 (64 -> 32 -> 16 -> 8 -> 4 pixels), 2 dense layers of 256 units,
then the means and log-variances of 10 Gaussian latents; the decoder mirrors it and outputs
Bernoulli logits over pixels. Loss per image: BCE-with-logits summed over pixels + beta * KL
(summed over latents), or beta * |KL - C| with a capacity C rising linearly (the capacity
variant).

Two training aids, off by default (the paper has neither; docs/results.md F6 measured why they
matter on 2 CPU cores): ``mean_image_offset`` adds a fixed per-pixel offset, the logit of the
mean training image, to the decoder's logits, so that an untrained decoder already draws the
static scene and training spends its steps on what moves; ``kl_delay``/``kl_warmup`` leave the KL
term out for the first iterations and then raise its weight linearly to 1, so that the code is
informative before the KL term presses on it.

Images enter as BGR uint8 arrays (OpenCV order, as the rig and the run store keep them) of
shape (n, 64, 64, 3); ``to_tensor`` converts them to RGB float tensors (n, 3, 64, 64) in [0, 1].
A model is saved as a folder: ``vae.pt`` (the state dict, loaded with ``weights_only=True``) and
``vae.json`` (its ``VaeConfig``).

This module imports no other package of the project.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import warnings
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from plumbing.files import atomic_write
from vision.observation import OBSERVATION_SIZE

IMAGE_SIZE = OBSERVATION_SIZE  # 64, the paper (vision/observation.py)
CHANNELS = 32  # paper: 4 conv layers of 32 channels, 4x4, stride 2
HIDDEN = 256  # paper: 2 dense layers of 256
LATENT_DIM = 10  # paper: 10 Gaussian latents
MAX_THREADS = 2  # the project's CPU budget (2 cores shared)
MODEL_FILE, CONFIG_FILE = "vae.pt", "vae.json"
# The mean image's pixel values are clipped to [eps, 1 - eps] before their logit (a pixel that is
# 0 or 1 in every image would have an infinite one). A guess: any value that keeps the logits
# finite and small next to the decoder's own range (|logit| <= 6.9) serves.
OFFSET_EPS = 1e-3


class VaeError(ValueError):
    """Bad VAE input, configuration or model files."""


def read_config_json(path: Path, what: str) -> dict:
    """The JSON object in ``path`` (a model's config); a one-line ``VaeError`` for a file that
    is not one (empty, truncated, binary garbage, a list)."""
    try:
        raw = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as exc:  # JSONDecodeError is a ValueError
        raise VaeError(f"{path} is not a {what} config (not JSON: {exc}): damaged?") from exc
    if not isinstance(raw, dict):
        raise VaeError(f"{path} is not a {what} config (a JSON {type(raw).__name__})")
    return raw


def read_model_folder(
    path: str | Path, files: tuple[str, str], what: str, command: str
) -> tuple[Path, Path, dict]:
    """A model folder (or the model file in it) named by ``path``: its model file, its config
    file and the config's JSON object. ``files``: (model file, config file) names; ``what``:
    the kind of model for messages; ``command``: the command that writes such folders. A
    one-line ``VaeError`` where a file is missing or the config is not a JSON object."""
    path = Path(path)
    folder = path.parent if path.suffix == ".pt" else path
    model_file, config_file = folder / files[0], folder / files[1]
    for f in (model_file, config_file):
        if not f.is_file():
            raise VaeError(f"{f} not found: is {folder} a model folder from `{command}`?")
    return model_file, config_file, read_config_json(config_file, what)


def write_model_folder(
    folder: str | Path, files: tuple[str, str], state: dict, config: Any
) -> Path:
    """Write a model's ``state`` (its state dict) and ``config`` (a dataclass, as JSON) into
    ``folder`` under ``files`` (model file, config file names); returns the folder."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    save_state(state, folder / files[0])
    write_text_atomically(folder / files[1], json.dumps(asdict(config), indent=2))
    return folder


def load_state(path: Path, what: str) -> Any:
    """``torch.load`` of a file written by ``torch.save`` (tensors only); a one-line
    ``VaeError`` for one that is empty, truncated or not a torch file."""
    try:
        with warnings.catch_warnings():  # garbage can look like another pickle protocol
            warnings.simplefilter("ignore")
            return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # EOFError, UnpicklingError, RuntimeError (zip), OSError, ...
        detail = " ".join(str(exc).split())[:200] or type(exc).__name__
        raise VaeError(
            f"{path} is not a readable {what} ({detail}): damaged or truncated?"
        ) from exc


def save_state(obj: Any, path: Path) -> None:
    """``torch.save`` to ``path`` through a temporary file and a rename: a failure (a full
    disk: torch reports it as a ``RuntimeError``) leaves ``path`` as it was and no temporary
    file, and is a one-line ``VaeError``."""
    try:
        atomic_write(path, lambda tmp: torch.save(obj, tmp))
    except (RuntimeError, OSError) as exc:
        detail = " ".join(str(exc).split())[:200]
        with contextlib.suppress(OSError):  # torch's writer does not give the errno: look
            if shutil.disk_usage(path.parent).free < (1 << 20):
                detail = f"No space left on device: {detail}"
        raise VaeError(f"cannot write {path} ({detail})") from exc


def write_text_atomically(path: Path, text: str) -> None:
    """``path.write_text`` through a temporary file and a rename (no half file on failure)."""
    atomic_write(path, text)


def check_statistics(values: Any, length: int, name: str, where: Path) -> None:
    """``values`` is None or a list of ``length`` finite numbers (a model's statistics); a
    one-line ``VaeError`` otherwise."""
    if values is None:
        return
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise VaeError(f"{where}: {name} is not a list of numbers") from exc
    if arr.shape != (length,):
        raise VaeError(f"{where}: {name} has {arr.size} values, the model has {length}")
    if not np.all(np.isfinite(arr)):
        raise VaeError(f"{where}: {name} holds NaN or infinite values: damaged?")


def limit_threads(n: int = MAX_THREADS) -> None:
    """Use at most ``n`` CPU threads for torch (never more than it has)."""
    torch.set_num_threads(max(1, min(n, torch.get_num_threads())))


# Up to this many images an encoding runs on one thread: a single 64x64 image takes 2.2 ms on
# one and 2.1 ms on two (twice the CPU), and beside a second campaign worker OpenMP's waiting
# threads made it several times slower (measured 2026-12-01: rge-vae 34 ms an episode alone,
# 100 ms with two workers on 2 cores). Switching costs under a microsecond.
SINGLE_THREAD_BATCH = 16


@contextlib.contextmanager
def few_threads_for(n_images: int) -> Iterator[None]:
    """One torch thread while encoding at most ``SINGLE_THREAD_BATCH`` images (an episode's
    outcome), the usual count otherwise; restored on exit."""
    if n_images > SINGLE_THREAD_BATCH:
        yield
        return
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)


@dataclass
class VaeConfig:
    """Model and loss configuration (saved with the weights).

    Attributes:
        latent_dim, channels, hidden: architecture (paper: 10, 32, 256).
        beta: weight of the KL term (1: plain VAE; > 1: beta-VAE).
        capacity: final KL capacity C, nats (None: plain beta * KL).
        capacity_iterations: iterations over which C rises linearly from 0 to ``capacity``.
        kl_per_latent: mean KL of each latent over the training data (filled after training;
            ranks the latents into MGE modules).
        latent_mean, latent_std: mean and standard deviation of each latent mean over the
            training data (filled after training; a goal space can z-score latents with them).
        heldout_explained_variance: the model-selection criterion on the images held out of
            training (``vision.representation_quality``; filled when some were held out).
        mean_image_offset: the decoder's logits are added to the logit of the mean training
            image (a buffer (3, 64, 64) set by ``Vae.set_mean_image`` before training, saved
            with the weights).
        kl_delay, kl_warmup: the KL term's weight is 0 for the first ``kl_delay`` iterations,
            then rises linearly to 1 over ``kl_warmup`` iterations (both 0: always 1).
    """

    latent_dim: int = LATENT_DIM
    channels: int = CHANNELS
    hidden: int = HIDDEN
    beta: float = 1.0
    capacity: float | None = None
    capacity_iterations: int = 2000
    kl_per_latent: list[float] | None = field(default=None)
    latent_mean: list[float] | None = field(default=None)
    latent_std: list[float] | None = field(default=None)
    heldout_explained_variance: float | None = None
    mean_image_offset: bool = False
    kl_delay: int = 0
    kl_warmup: int = 0

    def kl_weight(self, iteration: int) -> float:
        """The KL term's weight at 0-based ``iteration`` (``kl_delay``, ``kl_warmup``)."""
        if iteration < self.kl_delay:
            return 0.0
        if self.kl_warmup == 0:
            return 1.0
        return min(1.0, (iteration - self.kl_delay) / self.kl_warmup)

    def validate(self) -> None:
        if self.latent_dim < 1 or self.channels < 1 or self.hidden < 1:
            raise VaeError("latent_dim, channels and hidden must be positive")
        if self.beta < 0:
            raise VaeError(f"beta must be >= 0, got {self.beta}")
        if self.capacity is not None and self.capacity < 0:
            raise VaeError(f"capacity must be >= 0, got {self.capacity}")
        if self.capacity_iterations < 1:
            raise VaeError("capacity_iterations must be at least 1")
        if self.kl_delay < 0 or self.kl_warmup < 0:
            raise VaeError(
                f"kl_delay and kl_warmup must be >= 0, got {self.kl_delay}, {self.kl_warmup}"
            )


def to_tensor(images: np.ndarray) -> torch.Tensor:
    """BGR uint8 images (n, 64, 64, 3) -> RGB float tensor (n, 3, 64, 64) in [0, 1]."""
    a = np.asarray(images)
    if a.ndim != 4 or a.shape[1:] != (IMAGE_SIZE, IMAGE_SIZE, 3):
        raise VaeError(f"images have shape {a.shape}, expected (n, 64, 64, 3) BGR")
    if a.dtype != np.uint8:
        raise VaeError(f"images have dtype {a.dtype}, expected uint8")
    t = torch.from_numpy(np.ascontiguousarray(a[..., ::-1]))  # BGR -> RGB
    return t.permute(0, 3, 1, 2).float().div_(255.0)


class Vae(nn.Module):
    """Convolutional VAE with a Bernoulli decoder."""

    def __init__(self, config: VaeConfig | None = None) -> None:
        super().__init__()
        self.config = config or VaeConfig()
        self.config.validate()
        c, h, z = self.config.channels, self.config.hidden, self.config.latent_dim
        self.flat = c * 4 * 4  # 64 / 2^4 = 4
        self.encoder = nn.Sequential(
            nn.Conv2d(3, c, 4, 2, 1), nn.ReLU(),
            nn.Conv2d(c, c, 4, 2, 1), nn.ReLU(),
            nn.Conv2d(c, c, 4, 2, 1), nn.ReLU(),
            nn.Conv2d(c, c, 4, 2, 1), nn.ReLU(),
            nn.Flatten(),
            nn.Linear(self.flat, h), nn.ReLU(),
            nn.Linear(h, h), nn.ReLU(),
            nn.Linear(h, 2 * z),
        )  # fmt: skip
        self.decoder_fc = nn.Sequential(
            nn.Linear(z, h), nn.ReLU(),
            nn.Linear(h, h), nn.ReLU(),
            nn.Linear(h, self.flat), nn.ReLU(),
        )  # fmt: skip
        self.decoder_conv = nn.Sequential(
            nn.ConvTranspose2d(c, c, 4, 2, 1), nn.ReLU(),
            nn.ConvTranspose2d(c, c, 4, 2, 1), nn.ReLU(),
            nn.ConvTranspose2d(c, c, 4, 2, 1), nn.ReLU(),
            nn.ConvTranspose2d(c, 3, 4, 2, 1),
        )  # fmt: skip
        if self.config.mean_image_offset:
            self.register_buffer("pixel_offset", torch.zeros(3, IMAGE_SIZE, IMAGE_SIZE))

    def set_mean_image(self, images: np.ndarray) -> None:
        """Set the decoder's per-pixel offset to the logit of the mean of ``images`` (n, 64, 64,
        3) BGR uint8, clipped to [OFFSET_EPS, 1 - OFFSET_EPS] (``mean_image_offset`` only)."""
        if not self.config.mean_image_offset:
            raise VaeError("this VAE has no mean-image offset (mean_image_offset is off)")
        if len(images) == 0:
            raise VaeError("no images to take the mean of")
        total = torch.zeros(3, IMAGE_SIZE, IMAGE_SIZE, dtype=torch.float64)
        for i in range(0, len(images), 512):
            total += to_tensor(images[i : i + 512]).double().sum(dim=0)
        p = (total / len(images)).clamp(OFFSET_EPS, 1.0 - OFFSET_EPS)
        self.pixel_offset.copy_((p.log() - (-p).log1p()).float())

    # ---- the model ---------------------------------------------------------------------------
    def encode(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """x (n, 3, 64, 64) in [0, 1] -> means and log-variances, each (n, latent_dim)."""
        mu, logvar = self.encoder(x).chunk(2, dim=1)
        return mu, logvar

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """z (n, latent_dim) -> pixel logits (n, 3, 64, 64)."""
        c = self.config.channels
        logits = self.decoder_conv(self.decoder_fc(z).view(-1, c, 4, 4))
        return logits + self.pixel_offset if self.config.mean_image_offset else logits

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Returns (logits (n, 3, 64, 64), mu (n, z), logvar (n, z)); samples z in training."""
        mu, logvar = self.encode(x)
        z = mu + torch.randn_like(mu) * torch.exp(0.5 * logvar) if self.training else mu
        return self.decode(z), mu, logvar

    def loss(self, x: torch.Tensor, iteration: int = 0) -> dict[str, torch.Tensor]:
        """Batch-mean loss terms: ``loss`` (to minimise), ``recon`` (BCE summed over pixels),
        ``kl`` (summed over latents), nats per image."""
        logits, mu, logvar = self(x)
        recon = F.binary_cross_entropy_with_logits(logits, x, reduction="sum") / len(x)
        kl = kl_per_latent(mu, logvar).sum(dim=1).mean()
        cfg = self.config
        beta = cfg.beta * cfg.kl_weight(iteration)
        if cfg.capacity is None:
            total = recon + beta * kl
        else:
            c = cfg.capacity * min(1.0, iteration / cfg.capacity_iterations)
            total = recon + beta * (kl - c).abs()
        return {"loss": total, "recon": recon, "kl": kl}

    # ---- numpy API ---------------------------------------------------------------------------
    @torch.no_grad()
    def encode_bgr(self, images: np.ndarray, batch: int = 256) -> np.ndarray:
        """Latent means of BGR uint8 images (n, 64, 64, 3) -> (n, latent_dim) float64."""
        was = self.training
        if was:  # eval()/train() walk every module: 0.4 ms, a fifth of one image's encoding
            self.eval()
        with few_threads_for(len(images)):
            out = [
                self.encode(to_tensor(images[i : i + batch]))[0].double().numpy()
                for i in range(0, len(images), batch)
            ]
        if was:
            self.train(True)
        return np.concatenate(out) if out else np.zeros((0, self.config.latent_dim))

    @torch.no_grad()
    def decode_bgr(self, z: np.ndarray) -> np.ndarray:
        """Latents (n, latent_dim) -> reconstructed BGR uint8 images (n, 64, 64, 3)."""
        zt = torch.as_tensor(np.asarray(z, dtype=np.float32)).reshape(-1, self.config.latent_dim)
        rgb = torch.sigmoid(self.decode(zt)).permute(0, 2, 3, 1).numpy()
        return np.ascontiguousarray((rgb[..., ::-1] * 255.0 + 0.5).astype(np.uint8))

    @torch.no_grad()
    def mean_kl_per_latent(self, images: np.ndarray, batch: int = 256) -> list[float]:
        """Mean KL of each latent to the prior over ``images``, nats, length latent_dim."""
        was = self.training
        self.eval()
        total = torch.zeros(self.config.latent_dim, dtype=torch.float64)
        for i in range(0, len(images), batch):
            mu, logvar = self.encode(to_tensor(images[i : i + batch]))
            total += kl_per_latent(mu, logvar).double().sum(dim=0)
        self.train(was)
        return (total / max(len(images), 1)).tolist()

    def latent_stats(self, images: np.ndarray) -> tuple[list[float], list[float]]:
        """Mean and standard deviation of each latent mean over ``images`` (n, 64, 64, 3) BGR
        uint8: two lists of length latent_dim."""
        mu = self.encode_bgr(images)
        if len(mu) == 0:
            raise VaeError("no images to measure latent statistics on")
        return mu.mean(axis=0).tolist(), mu.std(axis=0).tolist()

    # ---- files -------------------------------------------------------------------------------
    def save(self, folder: str | Path) -> Path:
        """Write ``vae.pt`` and ``vae.json`` into ``folder``; returns the folder."""
        return write_model_folder(folder, (MODEL_FILE, CONFIG_FILE), self.state_dict(), self.config)


def kl_per_latent(mu: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
    """KL(N(mu, exp(logvar)) || N(0, 1)) per latent, shape (n, latent_dim), nats."""
    return 0.5 * (mu.pow(2) + logvar.exp() - 1.0 - logvar)


def load_vae(path: str | Path) -> Vae:
    """Load a model folder (or its ``vae.pt``) saved by ``Vae.save``, in eval mode."""
    model_file, config_file, raw = read_model_folder(
        path, (MODEL_FILE, CONFIG_FILE), "VAE", "ergo vae train"
    )
    try:
        config = VaeConfig(**raw)
        vae = Vae(config)
    except (TypeError, ValueError, RuntimeError) as exc:
        raise VaeError(f"{config_file} is not a VAE config: {exc}") from exc
    for name in ("kl_per_latent", "latent_mean", "latent_std"):
        check_statistics(getattr(config, name), config.latent_dim, name, config_file)
    state = load_state(model_file, "VAE model")
    try:
        vae.load_state_dict(state)
    except (RuntimeError, KeyError, TypeError, AttributeError) as exc:
        raise VaeError(f"{model_file} does not match its config: {exc}") from exc
    vae.eval()
    return vae
