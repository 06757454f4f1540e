"""Training a ``vision.vae.Vae`` (and, with ``fit``, any representation of 64x64 observations)
on an image database: progress, checkpoints, resume.

Deterministic given the data and the seed: the batch of iteration i is drawn by
``numpy.random.default_rng([seed, i])`` and the reparameterisation noise by
``torch.manual_seed(seed * 1_000_003 + i)``, so a run resumed from a checkpoint continues exactly
as the uninterrupted run would have (same thread count, same machine). On a CUDA device
(``device="cuda"``, or ``"auto"`` where one is present) the data are kept on the GPU and a
resumed run continues from the same weights, but cuDNN's kernels are not bitwise reproducible.

The paper trained 300k iterations at lr 1e-5 (batch 64) on a GPU. On 2 CPU cores we train with
Adam at lr 1e-3, batch 64, for a few thousand iterations; measured cost and the posterior
collapse seen after 300 iterations: docs/goal_exploration.md.

Files in the output folder: ``checkpoint.pt`` (weights, optimiser, iteration; written every
``checkpoint_every`` iterations and at the end), ``train_log.csv`` (iteration, loss, recon, kl),
and the final ``vae.pt`` + ``vae.json`` (``Vae.save``).
"""

from __future__ import annotations

import math
import sys
import zipfile
import zlib
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from vision.representation_quality import explained_pixel_variance, heldout_split
from vision.vae import (
    MAX_THREADS,
    Vae,
    VaeConfig,
    VaeError,
    limit_threads,
    load_state,
    save_state,
    to_tensor,
)

CHECKPOINT = "checkpoint.pt"
LOG = "train_log.csv"
KL_SAMPLE = 2000  # images used to measure the KL per latent after training (guess: enough)


@dataclass
class TrainConfig:
    """Optimisation settings.

    Attributes:
        iterations: total gradient steps (a guess: 300 measured were not enough, the latents had
            collapsed; docs/goal_exploration.md; 0.11-0.12 s of CPU each at batch 64 on one
            thread, 2026-12-03, docs/results.md F6).
        lr: Adam learning rate (paper 1e-5 over 300k iterations; 1e-3 here, a guess for short runs).
        lr_final: None: ``lr`` throughout; else the rate decays from ``lr`` at the first
            iteration to ``lr_final`` at the last along a half cosine (``lr_at``). The rates
            depend on ``iterations``: a run resumed with another total follows the new
            schedule from where it stopped.
        batch: images per step (paper 64).
        seed: seeds batches and sampling noise.
        checkpoint_every: iterations between checkpoints.
        threads: torch CPU threads (at most 2 on this project's machines).
        channels_last: the model's convolution weights and every batch in the channels-last
            memory layout (measured 2026-12-03 on 1 thread, two trainings side by side on 2
            cores: 0.114 s of CPU an iteration against 0.124 contiguous; docs/results.md F6).
        device: "cpu", "cuda" (a GPU; an error where there is none) or "auto" (the GPU where
            one is present). The returned and saved model is on the CPU either way.
    """

    iterations: int = 3000
    lr: float = 1e-3
    lr_final: float | None = None
    batch: int = 64
    seed: int = 0
    checkpoint_every: int = 250
    threads: int = MAX_THREADS
    device: str = "cpu"
    channels_last: bool = False

    def validate(self) -> None:
        if self.iterations < 1 or self.batch < 1 or self.checkpoint_every < 1:
            raise VaeError("iterations, batch and checkpoint_every must be positive")
        if not self.lr > 0:
            raise VaeError(f"lr must be positive, got {self.lr}")
        if self.lr_final is not None and not 0 < self.lr_final <= self.lr:
            raise VaeError(f"lr_final must be in (0, lr = {self.lr}], got {self.lr_final}")
        if self.device not in DEVICES:
            raise VaeError(f"device must be one of {', '.join(DEVICES)}, got {self.device!r}")

    def lr_at(self, iteration: int) -> float:
        """The learning rate of 0-based ``iteration``: ``lr``, or the half-cosine decay from
        ``lr`` (first iteration) to ``lr_final`` (last)."""
        if self.lr_final is None:
            return self.lr
        frac = min(1.0, iteration / max(1, self.iterations - 1))
        return self.lr_final + 0.5 * (self.lr - self.lr_final) * (1.0 + math.cos(math.pi * frac))


DEVICES = ("cpu", "cuda", "auto")


def resolve_device(name: str) -> torch.device:
    """The torch device for ``name`` ("cpu", "cuda" or "auto": CUDA where present)."""
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cuda" and not torch.cuda.is_available():
        raise VaeError(
            f"device cuda asked for, but torch {torch.__version__} sees no CUDA GPU "
            "(use --device cpu or auto)"
        )
    return torch.device(name)


def batch_tensor(data: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """Images ``data[idx]`` of a BGR uint8 tensor (n, 64, 64, 3), on its device, as an RGB
    float tensor (b, 3, 64, 64) in [0, 1]: ``to_tensor`` without leaving the device."""
    return data[idx].flip(-1).permute(0, 3, 1, 2).float().div_(255.0)


def load_images(path: str | Path) -> np.ndarray:
    """The ``images`` array (n, 64, 64, 3) BGR uint8 of a dataset ``.npz``."""
    path = Path(path)
    if not path.is_file():
        raise VaeError(f"{path}: no such dataset file (make one with `ergo dataset outcomes`)")
    try:
        z = np.load(path, allow_pickle=False)
        if not isinstance(z, np.lib.npyio.NpzFile):  # an .npy: one array, not an archive
            raise VaeError(f"{path}: a single .npy array, not a dataset (.npz) of `ergo dataset`")
        with z:
            images = z["images"]
    except VaeError:
        raise
    except (KeyError, ValueError, OSError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
        detail = " ".join(str(exc).split())[:200] or type(exc).__name__
        raise VaeError(
            f"{path}: not a dataset with an 'images' array ({detail}): damaged or truncated?"
        ) from exc
    to_tensor(images[:1])  # checks shape and dtype
    return images


def train_vae(
    images: np.ndarray,
    out: str | Path,
    model_config: VaeConfig | None = None,
    config: TrainConfig | None = None,
    progress: bool = True,
    heldout: float = 0.0,
) -> Vae:
    """Train (or resume training) a VAE on ``images`` (n, 64, 64, 3) BGR uint8 into ``out``.

    An existing checkpoint in ``out`` is resumed (its model config wins; a different one given
    here is refused). ``heldout``: share of the images kept out of training (a split seeded by
    the training seed) to score the model (``VaeConfig.heldout_explained_variance``). Returns
    the trained model, also saved as ``out/vae.pt`` + ``vae.json``.
    """
    config = config or TrainConfig()
    model_config = model_config or VaeConfig()
    images = np.asarray(images)
    train_idx, test_idx = heldout_split(len(images), heldout, config.seed)
    train = images[train_idx] if len(test_idx) else images
    vae = fit(
        lambda settings: make_vae(settings, train), asdict(_without_statistics(model_config)),
        train, out, config, progress, desc="vae",
    )  # fmt: skip
    sample = train[np.random.default_rng(config.seed).permutation(len(train))[:KL_SAMPLE]]
    vae.config.kl_per_latent = vae.mean_kl_per_latent(sample)
    vae.config.latent_mean, vae.config.latent_std = vae.latent_stats(sample)
    if len(test_idx):
        vae.config.heldout_explained_variance = explained_pixel_variance(
            lambda x: vae.decode_bgr(vae.encode_bgr(x)), images[test_idx],
            train.astype(np.float64).mean(axis=0),
        )  # fmt: skip
    vae.save(out)
    return vae


def make_vae(settings: dict[str, Any], images: np.ndarray) -> Vae:
    """A fresh VAE of ``settings`` (``VaeConfig`` fields) for training on ``images`` (n, 64, 64,
    3) BGR uint8: with ``mean_image_offset``, its offset is their mean image's logit (a resumed
    training then loads the saved one, the same)."""
    vae = Vae(VaeConfig(**settings))
    if vae.config.mean_image_offset:
        vae.set_mean_image(images)
    return vae


def fit(
    make_model: Callable[[dict[str, Any]], torch.nn.Module],
    settings: dict[str, Any],
    images: np.ndarray,
    out: str | Path,
    config: TrainConfig,
    progress: bool = True,
    desc: str = "train",
    after_step: Callable[[torch.nn.Module, int], bool] | None = None,
) -> Any:
    """The training loop of every representation: ``make_model(settings)`` (a module with a
    ``loss(x, iteration) -> dict`` whose ``"loss"`` is minimised; the other terms are logged)
    trained on ``images`` (n, 64, 64, 3) BGR uint8 with Adam, checkpointed into ``out`` and
    resumed from there (the checkpoint's settings must equal ``settings``). ``after_step``,
    if given, is called with the model and the iterations done after every step; True stops
    the training there (checkpointed, as at the end). Returns the model
    on the CPU in eval mode; the caller measures and saves it."""
    config.validate()
    if len(images) < 1:
        raise VaeError("no images to train on")
    to_tensor(images[:1])
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    limit_threads(config.threads)
    device = resolve_device(config.device)
    start = 0
    ckpt_path = out / CHECKPOINT
    state = None
    if ckpt_path.exists():
        state = load_state(ckpt_path, "training checkpoint")
        if not isinstance(state, dict) or not {
            "model",
            "optim",
            "iteration",
            "model_config",
        } <= set(state):
            raise VaeError(
                f"{ckpt_path} is not a training checkpoint (damaged?): remove it to train from "
                "the start"
            )
        if state["model_config"] != settings:
            raise VaeError(
                f"{ckpt_path} was trained with {state['model_config']}; remove it or use the "
                "same settings to resume"
            )
        start = int(state["iteration"])
    torch.manual_seed(config.seed)  # initial weights
    model = make_model(settings)
    if state is not None:
        model.load_state_dict(state["model"])
    layout = torch.channels_last if config.channels_last else torch.contiguous_format
    model.to(device, memory_format=layout)
    optim = torch.optim.Adam(model.parameters(), lr=config.lr)
    if state is not None:
        optim.load_state_dict(state["optim"])  # moved onto the parameters' device
    data = torch.from_numpy(np.ascontiguousarray(images)).to(device)  # uint8, per batch
    bar = None
    if progress and start < config.iterations:
        from tqdm import tqdm

        bar = tqdm(total=config.iterations, initial=start, unit="it", file=sys.stderr,
                   mininterval=1.0, desc=desc)  # fmt: skip
    log_rows: list[str] = []
    header = ""
    model.train()
    for it in range(start, config.iterations):
        idx = np.random.default_rng([config.seed, it]).integers(0, len(images), config.batch)
        torch.manual_seed(config.seed * 1_000_003 + it)
        x = batch_tensor(data, torch.from_numpy(idx).to(device)).contiguous(memory_format=layout)
        for group in optim.param_groups:
            group["lr"] = config.lr_at(it)
        terms = model.loss(x, it)
        optim.zero_grad(set_to_none=True)
        terms["loss"].backward()
        optim.step()
        if it % 10 == 0 or it == config.iterations - 1:
            vals = {k: float(v.detach()) for k, v in terms.items()}
            header = ",".join(["iteration", *vals])
            log_rows.append(",".join([str(it), *(f"{v:.3f}" for v in vals.values())]))
            if bar is not None:
                bar.set_postfix({k: f"{v:.1f}" for k, v in vals.items() if k != "recon"},
                                refresh=False)  # fmt: skip
        if bar is not None:
            bar.update(1)
        done = it + 1
        stop = after_step is not None and after_step(model, done)
        if stop or done % config.checkpoint_every == 0 or done == config.iterations:
            _checkpoint(ckpt_path, model, optim, done, settings)
            _append_log(out / LOG, header, log_rows)
            log_rows = []
        if stop:
            break
    if bar is not None:
        bar.close()
    return model.to("cpu", memory_format=torch.contiguous_format).eval()


def _without_statistics(config: VaeConfig) -> VaeConfig:
    """A copy of ``config`` with the statistics measured after training cleared (they are not
    settings)."""
    return replace(
        config, kl_per_latent=None, latent_mean=None, latent_std=None,
        heldout_explained_variance=None,
    )  # fmt: skip


def _checkpoint(
    path: Path,
    model: torch.nn.Module,
    optim: torch.optim.Optimizer,
    iteration: int,
    settings: dict[str, Any],
) -> None:
    save_state(
        {"model": model.state_dict(), "optim": optim.state_dict(), "iteration": iteration,
         "model_config": settings},
        path,
    )  # fmt: skip


def _append_log(path: Path, header: str, rows: list[str]) -> None:
    new = not path.exists()
    with open(path, "a") as f:
        if new:
            f.write(header + "\n")
        for r in rows:
            f.write(r + "\n")
